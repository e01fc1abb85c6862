#version 460
// DFSPH's factor alpha_i (Bender & Koschier 2017, eq. 11), one invocation per particle, after
// compute_density: alpha_i = omega / (|sum_j V grad W_ij|^2 + sum_j |V grad W_ij|^2), V = m / rho_0, over the
// neighbours and their wall and obstacle images (as in compute_density); omega = fluid.relaxation, the
// share of each Jacobi update the solves apply (1: the paper's and SPlisHSPlasH's). Also starts the step's two
// solves (dfsph.glsl): invocation 0 clears their done flags and iteration counts and sets their indirect
// dispatches' work groups (one invocation per particle); every particle's
// pressure is cleared and its stiffness sum scaled to the warm start (WARM_START). The sums walk the
// particle's neighbour list (walk.glsl: walk_list), which compute_density's scan wrote; with GRADIENTS they store each entry's
// V grad W_ij (neighbour_gradients) for the solves' sweeps, which then read it instead of computing the pair
// again (dfsph.glsl). The sum of each particle's V grad W_ij goes to particle_gradient_sum (dfsph_residual).
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
layout(std430, binding = 22) writeonly buffer ParticleAlpha { real particle_alpha[]; };
layout(std430, binding = 24) buffer Control { uint control[]; };
layout(std430, binding = 25) readonly buffer DfsphState { float dfsph_state[]; };
layout(std430, binding = 27) buffer ParticleKappa { real particle_kappa[]; };
layout(std430, binding = 29) readonly buffer Neighbours { uint neighbours[]; };
layout(std430, binding = 29) readonly buffer NeighbourChunks { uvec4 neighbour_chunks[]; };  // (the same, by chunks)
layout(std430, binding = 30) readonly buffer NeighbourCount { uint neighbour_count[]; };
layout(std430, binding = 31) writeonly buffer NeighbourGradients { real4 neighbour_gradients[]; };
layout(std430, binding = 19) writeonly buffer ParticleVh { real4 particle_gradient_sum[]; };  // (DFSPH: no Verlet)
layout(std430, binding = 8) readonly buffer CellPyramid { uint cell_pyramid[]; };  // (unread: named by walk.glsl)
layout(std430, binding = 9) readonly buffer CellStart { uint cell_start[]; };  // (unread: named by walk.glsl)
layout(std430, binding = 11) readonly buffer ScratchX { real4 scratch_x[]; };  // (unread: named by walk.glsl)
#include "neighbour_list.glsl"

// i's position, walls and sums, private to the invocation: set by main, read and summed by `list_entry` over
// the walk
real3 xi;
real3 wall;
real3 inward;
real coef;
real3 sum_grad;
real sum_grad2;

// One entry of i's list (walk.glsl: walk_list hands over each slot): the neighbour j, or its image, and the
// direction from it to i (neighbour_list.glsl); g = V grad_i W_ij into the sums, and with GRADIENTS stored at
// the entry's slot.
void list_entry(uint i, uint slot, inout uvec4 chunk) {
    uint j;
    uint image;
    real3 r;
    real r2;
    real rlen;
    real3 r_hat = listed_pair(i, slot, chunk, xi, wall, inward, j, image, r, r2, rlen);
    real g = coef * pair_gradient(r2, rlen, image);
    real3 grad = g * r_hat;
    sum_grad -= grad;
    sum_grad2 += g * g;
    if (GRADIENTS) neighbour_gradients[list_slot(i, slot)] = real4(-grad, 0.0);
}
#include "walk.glsl"

void main() {
    // [1] one invocation per particle; invocation 0 also starts the step's solves
    uint i = gl_GlobalInvocationID.x;
    if (i >= P.n) return;
    if (i == 0u) {
        control[CONTROL_DONE + SOLVE_DIVERGENCE] = 0u;
        control[CONTROL_DONE + SOLVE_DENSITY] = 0u;
        control[CONTROL_ITERATIONS + SOLVE_DIVERGENCE] = 0u;
        control[CONTROL_ITERATIONS + SOLVE_DENSITY] = 0u;
        for (uint solve = SOLVE_DIVERGENCE; solve <= SOLVE_DENSITY; ++solve) {
            uint base = dispatch_base(solve);
            control[base] = (P.n + gl_WorkGroupSize.x - 1u) / gl_WorkGroupSize.x;
            control[base + 1u] = 1u;
            control[base + 2u] = 1u;
        }
    }
    // [2] own position; wall and obstacle images as in compute_density
    xi = particle_x[i].xyz;
    uint mirrored = near_walls(xi, wall);
    mirrored = near_obstacles(xi, mirrored, wall, inward);
    // [3] sums over the particle's list (compute_density wrote it this step, in its scan's order: every
    //     other particle and every image within h) of g = V grad_i W_ij = -coef kernel_gradient r_hat
    //     (coef = pressure_coef / rho_0): their sum, and the sum of |g|^2; with GRADIENTS each g stored for
    //     the solves' sweeps (the positions do not move before integrate); walk.glsl: walk_list, list_entry above
    coef = real(P.pressure_coef) / real(P.rest_density);
    sum_grad = real3(0.0);
    sum_grad2 = real(0.0);
    uint count = neighbour_count[i];
    walk_list(i, min(count, MAX_NEIGHBOURS));
    // [4] alpha_i, relaxed; 0 for a particle (nearly) alone, whose residual is 0 anyway
    real s = sum_grad.x * sum_grad.x + sum_grad.y * sum_grad.y + sum_grad.z * sum_grad.z + sum_grad2;
    real alpha = real(0.0);
    if (s > real(1e-6) / real(P.h2)) alpha = real(1.0) / s;
    alpha *= real(dfsph_state[STATE_RELAXATION]);
    // [5] store; the pressure starts from 0 and the stiffness sum from WARM_START times the last step's
    //     (dfsph_velocity accumulates both)
    particle_alpha[i] = alpha;
    particle_gradient_sum[i] = real4(sum_grad, 0.0);
    particle_p[i] = real(0.0);
    particle_kappa[i] = real(WARM_START) * particle_kappa[i];
    // [6] a list too long for its MAX_NEIGHBOURS slots marks the step (the same value from every
    //     invocation that writes it), and the host stops the run
    if (count > MAX_NEIGHBOURS && control[CONTROL_OVERFLOW_STEP] == 0u)
        control[CONTROL_OVERFLOW_STEP] = control[CONTROL_STEP] + 1u;
}
