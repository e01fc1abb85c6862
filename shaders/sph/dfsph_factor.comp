#version 460
// DFSPH's factor alpha_i (Bender & Koschier 2017, eq. 11), one invocation per particle, after
// compute_density: alpha_i = 1 / (|sum_j V grad W_ij|^2 + sum_j |V grad W_ij|^2), V = m / rho_0, over the
// neighbours and their wall and obstacle images (as in compute_density). Also starts the step's two
// solves (dfsph.glsl): invocation 0 clears their done flags and iteration counts and sets their indirect
// dispatches' work groups (one invocation per particle, and one group for the check); every particle's
// pressure is cleared and its stiffness sum scaled to the warm start (WARM_START). The scan also writes the
// particle's neighbour list, which every sweep of the solves walks (dfsph.glsl).
// Mirror: sphcore/sph/dfsph_factor.py (same names, same statement order, same step labels).
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

layout(std430, binding = 0) readonly buffer ParticleX { real4 particle_x[]; };
layout(std430, binding = 4) writeonly buffer ParticleP { real particle_p[]; };
layout(std430, binding = 8) readonly buffer CellPyramid { uint cell_pyramid[]; };
layout(std430, binding = 9) readonly buffer CellStart { uint cell_start[]; };
layout(std430, binding = 22) writeonly buffer ParticleAlpha { real particle_alpha[]; };
layout(std430, binding = 24) buffer DfsphControl { uint dfsph_control[]; };
layout(std430, binding = 27) buffer ParticleKappa { real particle_kappa[]; };
layout(std430, binding = 29) writeonly buffer DfsphNeighbours { uint dfsph_neighbours[]; };
layout(std430, binding = 30) writeonly buffer DfsphNeighbourCount { uint dfsph_neighbour_count[]; };

void main() {
    // [1] one invocation per particle; invocation 0 also starts the step's solves
    uint i = gl_GlobalInvocationID.x;
    if (i >= P.n) return;
    if (i == 0u) {
        dfsph_control[CONTROL_DONE + SOLVE_DIVERGENCE] = 0u;
        dfsph_control[CONTROL_DONE + SOLVE_DENSITY] = 0u;
        dfsph_control[CONTROL_ITERATIONS + SOLVE_DIVERGENCE] = 0u;
        dfsph_control[CONTROL_ITERATIONS + SOLVE_DENSITY] = 0u;
        for (uint solve = SOLVE_DIVERGENCE; solve <= SOLVE_DENSITY; ++solve) {
            uint base = dispatch_base(solve);
            dfsph_control[base] = (P.n + gl_WorkGroupSize.x - 1u) / gl_WorkGroupSize.x;
            dfsph_control[base + 1u] = 1u;
            dfsph_control[base + 2u] = 1u;
        }
    }
    // [2] own position; wall and obstacle images as in compute_density
    real3 xi = particle_x[i].xyz;
    real3 wall;
    uint mirrored = near_walls(xi, wall);
    real3 inward;
    mirrored = near_obstacles(xi, mirrored, wall, inward);
    // [3] sums over every other particle and every image within h of g = V grad_i W_ij = -coef
    //     kernel_gradient r_hat (coef = pressure_coef / rho_0): their sum, and the sum of |g|^2; each
    //     of them into the list, in the scan's order (dfsph.glsl)
    real coef = real(P.pressure_coef) / real(P.rest_density);
    real3 sum_grad = real3(0.0);
    real sum_grad2 = real(0.0);
    uint count = 0u;
    for (uint image = 0u; image < 8u; ++image) {
        if ((image & ~mirrored) != 0u) continue;
        real3 xm = reflected(xi, wall, image);
        ivec3 base = cell_of(xm);
        // [4] the 3^dim cells around xm, as ranges of sorted particles (cells.glsl: range_cells)
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
                real rlen = sqrt(r2);
                // [5] direction from the neighbour to i (pairs.glsl)
                real3 r_hat = pair_direction(r, rlen, i, j, image, inward);
                real g = coef * pair_gradient(r2, rlen, image);
                sum_grad -= g * r_hat;
                sum_grad2 += g * g;
                if (count < MAX_NEIGHBOURS) dfsph_neighbours[count * P.n + i] = j | (image << IMAGE_SHIFT);
                count += 1u;
            }
        }
    }
    // [6] alpha_i; 0 for a particle (nearly) alone, whose residual is 0 anyway
    real s = sum_grad.x * sum_grad.x + sum_grad.y * sum_grad.y + sum_grad.z * sum_grad.z + sum_grad2;
    real alpha = real(0.0);
    if (s > real(1e-6) / real(P.h2)) alpha = real(1.0) / s;
    // [7] store; the pressure starts from 0 and the stiffness sum from WARM_START times the last step's
    //     (dfsph_velocity accumulates both)
    particle_alpha[i] = alpha;
    particle_p[i] = real(0.0);
    particle_kappa[i] = real(WARM_START) * particle_kappa[i];
    // [8] the list's length; one too long for its MAX_NEIGHBOURS slots marks the step (the same value from
    //     every invocation that writes it), and the host stops the run
    dfsph_neighbour_count[i] = count;
    if (count > MAX_NEIGHBOURS && dfsph_control[CONTROL_OVERFLOW_STEP] == 0u)
        dfsph_control[CONTROL_OVERFLOW_STEP] = dfsph_control[CONTROL_STEP] + 1u;
}
