#version 460
// Acceleration from pressure (spiky gradient), viscosity (Mueller et al. 2003) and gravity,
// one invocation per particle, all-pairs neighbours, mirror images at the walls.
// Mirror: sphcore/sph/compute_forces.py (same names, same statement order, same step labels).
#extension GL_GOOGLE_include_directive : require
layout(local_size_x_id = 0) in;
#include "params.glsl"

layout(std430, binding = 0) readonly buffer ParticleX { vec2 particle_x[]; };
layout(std430, binding = 1) readonly buffer ParticleV { vec2 particle_v[]; };
layout(std430, binding = 2) writeonly buffer ParticleA { vec2 particle_a[]; };
layout(std430, binding = 3) readonly buffer ParticleRho { float particle_rho[]; };
layout(std430, binding = 4) readonly buffer ParticleP { float particle_p[]; };

void main() {
    // [1] one invocation per particle; the grid is rounded up to whole work groups
    uint i = gl_GlobalInvocationID.x;
    if (i >= P.n) return;
    // [2] own state
    vec2 xi = particle_x[i];
    vec2 vi = particle_v[i];
    float rhoi = particle_rho[i];
    float pi = particle_p[i];
    float pi_rho2 = pi / (rhoi * rhoi);
    // [3] wall images, as in compute_density; an image's normal velocity is reversed (free slip)
    float wall_x = xi.x - P.box_min.x < P.h ? P.box_min.x : P.box_max.x;
    float wall_y = xi.y - P.box_min.y < P.h ? P.box_min.y : P.box_max.y;
    uint images_x = abs(xi.x - wall_x) < P.h ? 2u : 1u;
    uint images_y = abs(xi.y - wall_y) < P.h ? 2u : 1u;
    // [4] pressure acceleration and viscous force density summed over all other particles and all images within h
    vec2 f_pressure = vec2(0.0);
    vec2 f_viscosity = vec2(0.0);
    for (uint j = 0u; j < P.n; ++j) {
        vec2 xj = particle_x[j];
        vec2 vj = particle_v[j];
        float rhoj = particle_rho[j];
        float pj = particle_p[j];
        for (uint mx = 0u; mx < images_x; ++mx) {
            for (uint my = 0u; my < images_y; ++my) {
                if (j == i && mx == 0u && my == 0u) continue;
                float xk = mx == 0u ? xj.x : 2.0 * wall_x - xj.x;
                float yk = my == 0u ? xj.y : 2.0 * wall_y - xj.y;
                float vk_x = mx == 0u ? vj.x : -vj.x;
                float vk_y = my == 0u ? vj.y : -vj.y;
                vec2 r = xi - vec2(xk, yk);
                float r2 = r.x * r.x + r.y * r.y;
                if (r2 >= P.h2) continue;
                float rlen = sqrt(r2);
                float hr = P.h - rlen;
                // [5] direction from the neighbour to i. Where the two coincide (normalize(0) is NaN):
                //     an image coincides with i only on a wall, so push along the wall's inward
                //     normal; two particles are pushed apart along x, antisymmetrically in (i, j)
                //     so momentum is conserved
                vec2 r_hat = vec2(i < j ? -1.0 : 1.0, 0.0);
                if (mx == 1u) r_hat = vec2(wall_x == P.box_min.x ? 1.0 : -1.0, 0.0);
                if (my == 1u) r_hat = vec2(0.0, wall_y == P.box_min.y ? 1.0 : -1.0);
                if (rlen > 0.0) r_hat = r / rlen;
                // [6] pressure: -sum_j m (p_i / rho_i^2 + p_j / rho_j^2) grad W_spiky, the form that conserves
                //     momentum and energy with summation density (Monaghan 1992); grad W_spiky = -30/(pi h^5) (h - r)^2 r_hat.
                //     Mueller et al. (2003) and seed 1 use m (p_i + p_j) / (2 rho_j): that estimates grad p / 2,
                //     so a column at rest settles at twice its hydrostatic pressure, and it over-pushes
                //     low-density surface particles, which gains energy in a dam break
                float fp = P.pressure_coef * (pi_rho2 + pj / (rhoj * rhoj)) * hr * hr;
                f_pressure += fp * r_hat;
                // [7] viscosity: mu sum_j m (v_j - v_i) / rho_j lap W_visc, lap W_visc = 40/(pi h^5) (h - r)
                float fv = P.viscosity_coef / rhoj * hr;
                f_viscosity += fv * vec2(vk_x - vi.x, vk_y - vi.y);
            }
        }
    }
    // [8] a_i = f_pressure + f_viscosity / rho_i + g (f_pressure is already per unit mass)
    vec2 a = f_pressure + f_viscosity / rhoi + P.gravity;
    // [9] store
    particle_a[i] = a;
}
