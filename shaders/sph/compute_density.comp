#version 460
// Density and pressure, one invocation per particle, all-pairs neighbours.
// Mirror: sphcore/sph/compute_density.py (same names, same statement order, same step labels).
#extension GL_GOOGLE_include_directive : require
layout(local_size_x_id = 0) in;
#include "params.glsl"

layout(std430, binding = 0) readonly buffer ParticleX { vec2 particle_x[]; };
layout(std430, binding = 3) writeonly buffer ParticleRho { float particle_rho[]; };
layout(std430, binding = 4) writeonly buffer ParticleP { float particle_p[]; };

void main() {
    // [1] one invocation per particle; the grid is rounded up to whole work groups
    uint i = gl_GlobalInvocationID.x;
    if (i >= P.n) return;
    // [2] own position
    vec2 xi = particle_x[i];
    // [3] wall images: within h of a wall, particle i also sees every particle mirrored
    //     across that wall (ghost fluid: free-slip boundary of Takeda et al. 1994)
    float wall_x = xi.x - P.box_min.x < P.h ? P.box_min.x : P.box_max.x;
    float wall_y = xi.y - P.box_min.y < P.h ? P.box_min.y : P.box_max.y;
    uint images_x = abs(xi.x - wall_x) < P.h ? 2u : 1u;
    uint images_y = abs(xi.y - wall_y) < P.h ? 2u : 1u;
    // [4] sum (h^2 - r^2)^3 over all particles and their images within h, self included
    float sum_w = 0.0;
    for (uint j = 0u; j < P.n; ++j) {
        vec2 xj = particle_x[j];
        for (uint mx = 0u; mx < images_x; ++mx) {
            for (uint my = 0u; my < images_y; ++my) {
                float xk = mx == 0u ? xj.x : 2.0 * wall_x - xj.x;
                float yk = my == 0u ? xj.y : 2.0 * wall_y - xj.y;
                vec2 r = xi - vec2(xk, yk);
                float r2 = r.x * r.x + r.y * r.y;
                if (r2 < P.h2) {
                    float q = P.h2 - r2;
                    sum_w += q * q * q;
                }
            }
        }
    }
    // [5] rho_i = m sum_j W_poly6(r_ij, h)
    float rho = P.density_coef * sum_w;
    // [6] linear equation of state p = k (rho - rho_0), clamped at 0 so the free surface does not pull
    float p = max(P.stiffness * (rho - P.rest_density), 0.0);
    // [7] store
    particle_rho[i] = rho;
    particle_p[i] = p;
}
