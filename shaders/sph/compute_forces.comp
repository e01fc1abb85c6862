#version 460
// Acceleration from pressure (kernels.glsl: the kernel gradient), viscosity (laminar, Mueller et al. 2003, or artificial,
// Monaghan 1992: viscosity.glsl; wall images' velocities: walls.glsl), surface
// tension by cohesion (Becker & Teschner 2007) and gravity, one invocation per particle.
// Neighbours, wall and obstacle images as in compute_density; with neighbour lists (DFSPH, and the state
// equation where they fit: Scene.spec_for), the step's list (compute_density: the same pairs, in the same order,
// so the same bits; reused lists, LIST_SKIN: the pairs of the list now within h). Each optional term is compiled
// out by its specialization constant.
// Mirror: sphcore/sph/compute_forces.py (same names, same statement order, same step labels).
#extension GL_GOOGLE_include_directive : require
layout(local_size_x_id = 0) in;
#include "params.glsl"
#include "constants.glsl"
#include "real.glsl"
#include "cells.glsl"
#include "kernels.glsl"
#include "pairs.glsl"
#include "dfsph.glsl"

layout(std430, binding = 16) readonly buffer ObstacleBox { vec4 obstacle_box[]; };
#include "obstacles.glsl"
#include "walls.glsl"
#include "viscosity.glsl"

layout(std430, binding = 0) readonly buffer ParticleX { real4 particle_x[]; };
layout(std430, binding = 1) readonly buffer ParticleV { real4 particle_v[]; };
layout(std430, binding = 2) writeonly buffer ParticleA { real4 particle_a[]; };
layout(std430, binding = 3) readonly buffer ParticleRho { real particle_rho[]; };
layout(std430, binding = 4) readonly buffer ParticleP { real particle_p[]; };
layout(std430, binding = 8) readonly buffer CellPyramid { uint cell_pyramid[]; };
layout(std430, binding = 9) readonly buffer CellStart { uint cell_start[]; };
layout(std430, binding = 11) readonly buffer ScratchX { real4 scratch_x[]; };  // LIST_SKIN: x at the list's build
layout(std430, binding = 24) buffer Control { uint control[]; };  // LIST_SKIN: CONTROL_REBUILD
layout(std430, binding = 29) readonly buffer Neighbours { uint neighbours[]; };
layout(std430, binding = 29) readonly buffer NeighbourChunks { uvec4 neighbour_chunks[]; };  // (the same, by chunks)
layout(std430, binding = 30) readonly buffer NeighbourCount { uint neighbour_count[]; };
layout(std430, binding = 31) readonly buffer NeighbourGradients { real4 neighbour_gradients[]; };  // (unread: named by
                                                                                           // neighbour_list.glsl)
#include "neighbour_list.glsl"

void main() {
    // [1] one invocation per particle; the grid is rounded up to whole work groups
    uint i = gl_GlobalInvocationID.x;
    if (i >= P.n) return;
    // [2] own state
    real3 xi = particle_x[i].xyz;
    real3 vi = particle_v[i].xyz;
    real rhoi = particle_rho[i];
    real pi = particle_p[i];
    real pi_rho2 = pi / (rhoi * rhoi);
    // [3] wall and obstacle images, as in compute_density; an image's normal velocity is reversed
    //     (free slip); `inward` points from each axis's mirror plane into the fluid. Reused lists (LIST_SKIN):
    //     the walls and cells of where i was at the list's build, as compute_density's
    real3 x_built = LIST_SKIN > 0u ? scratch_x[i].xyz : xi;
    real3 wall;
    uint mirrored = LIST_SKIN > 0u ? near_walls_within(x_built, list_reach(), wall) : near_walls(xi, wall);
    real3 inward;
    mirrored = near_obstacles(xi, mirrored, wall, inward);
    // [4] sums over every other particle and every image within h
    real3 f_pressure = real3(0.0);
    real3 f_viscosity = real3(0.0);
    real3 f_cohesion = real3(0.0);
    // [5] with neighbour lists (Scene.spec_for), the list compute_density wrote from these
    //     positions this step (neighbour_list.glsl): the pairs of the scan below in its order, with the same
    //     terms as [8]-[10]. A particle with more neighbours than its list's slots is scanned instead
    bool listed = MAX_NEIGHBOURS > 0u && neighbour_count[i] <= MAX_NEIGHBOURS;
    if (listed) {
        uint count = neighbour_count[i];
        uvec4 chunk = uvec4(0u);
        for (uint slot = 0u; slot < count; ++slot) {
            uint j;
            uint image;
            real3 r;
            real r2;
            real rlen;
            real3 r_hat = listed_pair(i, slot, chunk, xi, wall, inward, j, image, r, r2, rlen);
            if (LIST_SKIN > 0u && r2 >= P.h2) continue;  // (a reused list holds pairs out to list_reach)
            real grad = pair_gradient(r2, rlen, image);
            real rhoj = particle_rho[j];
            if (!DFSPH) {
                real fp = P.pressure_coef * (pi_rho2 + particle_p[j] / (rhoj * rhoj)) * grad;
                f_pressure += fp * r_hat;
            }
            if (VISCOSITY) {
                real3 vk = image_velocity(particle_v[j].xyz, image);
                f_viscosity += viscous_term(vi, vk, r, r2, rhoi, rhoj, grad, kernel_laplacian(r2, rlen), r_hat);
            }
            if (SURFACE_TENSION && image == 0u) f_cohesion += kernel_w(r2) * r;
        }
    }
    for (uint image = 0u; image < 8u; ++image) {
        if (listed || (image & ~mirrored) != 0u) continue;
        real3 xm = reflected(x_built, wall, image);
        ivec3 base = cell_of(xm);
        // [6] the 3^dim cells around xm, as ranges of sorted particles (cells.glsl: range_cells)
        for (uint k = 0u; k < range_count(); ++k) {
            uint start = 0u;
            uint end = P.n;
            if (GRID) {
                int first;
                int last;
                if (!range_cells(base, k, first, last)) continue;
                start = cell_start[first];
                end = cell_start[last] + cell_pyramid[last];
            }
            for (uint j = start; j < end; ++j) {
                if (j == i && image == 0u) continue;
                real3 xk = particle_x[j].xyz;
                if (image != 0u) xk = reflected(xk, wall, image);
                if (OBSTACLES > 0u && image != 0u && !solid(xk)) continue;  // (obstacles.glsl)
                real3 r = xi - xk;
                real r2 = r.x * r.x + r.y * r.y + r.z * r.z;
                if (r2 >= P.h2) continue;
                real rhoj = particle_rho[j];
                real pj = particle_p[j];
                real rlen = sqrt(r2);
                real grad = pair_gradient(r2, rlen, image);  // kernels.glsl: m grad_i W_ij = -P.pressure_coef grad r_hat
                // [7] direction from the neighbour to i. Where the two coincide (normalize(0) is
                //     NaN): an image coincides with i only on a wall or an obstacle's face, so push
                //     along its inward normal; two particles are pushed apart along x,
                //     antisymmetrically in (i, j), so momentum is conserved
                real3 r_hat = pair_direction(r, rlen, i, j, image, inward);
                // [8] pressure: -sum_j m (p_i / rho_i^2 + p_j / rho_j^2) grad W (kernels.glsl), the form that
                //     conserves momentum and energy with summation or continuity density (Monaghan 1992).
                //     Mueller et al. (2003) and seed 1 use m (p_i + p_j) / (2 rho_j): that estimates
                //     grad p / 2, so a column at rest settles at twice its hydrostatic pressure
                real fp = P.pressure_coef * (pi_rho2 + pj / (rhoj * rhoj)) * grad;
                if (!DFSPH) f_pressure += fp * r_hat;  // DFSPH: the pressure is the solver's (dfsph.glsl)
                // [9] viscosity of the scene's model (viscosity.glsl: laminar, Mueller et al. 2003, or
                //     artificial, Monaghan 1992); an image's velocity is the wall model's (walls.glsl:
                //     free slip reverses its normal component, no slip all of it)
                if (VISCOSITY) {
                    real3 vk = image_velocity(particle_v[j].xyz, image);
                    f_viscosity += viscous_term(vi, vk, r, r2, rhoi, rhoj, grad, kernel_laplacian(r2, rlen), r_hat);
                }
                // [10] cohesion: -kappa sum_j W(r_ij) (x_i - x_j) (equal masses), between real
                //     particles only: the walls are not wetted
                if (SURFACE_TENSION && image == 0u) f_cohesion += kernel_w(r2) * r;
            }
        }
    }
    // [11] a_i = f_pressure + viscous acceleration + cohesion + g (f_pressure is per unit mass; the
    //      laminar sum is divided by rho_i, viscosity.glsl)
    real3 a = f_pressure;
    if (VISCOSITY) a += viscous_acceleration(f_viscosity, rhoi);
    if (SURFACE_TENSION) a += P.cohesion_coef * f_cohesion;
    if (GRAVITY) a += P.gravity;
    // [12] store; reused lists: the next build is integrate's to ask for (every dispatch that reads the request
    //      has run: backends.plan)
    particle_a[i] = real4(a, 0.0);
    if (LIST_SKIN > 0u && i == 0u) control[CONTROL_REBUILD] = 0u;
}
