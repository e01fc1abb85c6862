#version 460
// DFSPH's residual r_i of solve D.level (dfsph.glsl), one invocation per particle: the density
// ratio's rate d_i = sum_j V (v_i - v_j) . grad W_ij over its neighbour list (walk.glsl: walk_list; dfsph_factor: the neighbours
// and their wall and obstacle images; an image's velocity mirrored on its flipped axes, as compute_density's
// continuity rate), summed as v_i . G_i - sum_j V v_j . grad W_ij with G_i = sum_j V grad W_ij, which
// dfsph_factor stored (particle_gradient_sum): three subtractions fewer a pair.
//   divergence-free solve: r_i = max(d_i, 0) [1/s], with the velocity v;
//   constant-density solve: r_i = max(rho_i / rho_0 + dt d_i - 1, 0), with v* = v + dt a (the velocity
//   the step would integrate: dfsph_predict and dfsph_velocity keep it in scratch_v) and this step's dt
//   (time_state, choose_dt.comp).
// Only compression is corrected (a free surface's density deficit is not a tension). Invocation 0 of
// each work group sums the group's residuals in order into dfsph_partial, and counts the group as
// finished; the last group to finish runs the solve's convergence test (dfsph_check.glsl) over every
// group's sum, in the same dispatch. A solve's iterations are dispatched indirectly: no work groups once
// it has stopped.
// Mirror: sphcore/sph/dfsph_residual.py (same names, same statement order, same step labels; one
// local loop per phase between barriers).
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
layout(std430, binding = 1) readonly buffer ParticleV { real4 particle_v[]; };
layout(std430, binding = 3) readonly buffer ParticleRho { real particle_rho[]; };
layout(std430, binding = 12) readonly buffer ScratchV { real4 particle_vstar[]; };
layout(std430, binding = 20) readonly buffer TimeState { vec4 time_state[]; };
layout(std430, binding = 23) writeonly buffer ParticleResidual { real particle_residual[]; };
layout(std430, binding = 24) coherent buffer Control { uint control[]; };
layout(std430, binding = 25) buffer DfsphState { float dfsph_state[]; };
layout(std430, binding = 26) writeonly buffer DfsphHistory { float dfsph_history[]; };
layout(std430, binding = 28) coherent buffer DfsphPartial { real dfsph_partial[]; };
layout(std430, binding = 29) readonly buffer Neighbours { uint neighbours[]; };
layout(std430, binding = 29) readonly buffer NeighbourChunks { uvec4 neighbour_chunks[]; };  // (the same, by chunks)
layout(std430, binding = 30) readonly buffer NeighbourCount { uint neighbour_count[]; };
layout(std430, binding = 31) readonly buffer NeighbourGradients { real4 neighbour_gradients[]; };
layout(std430, binding = 19) readonly buffer ParticleVh { real4 particle_gradient_sum[]; };  // (DFSPH: no Verlet)
layout(std430, binding = 8) readonly buffer CellPyramid { uint cell_pyramid[]; };  // (unread: named by walk.glsl)
layout(std430, binding = 9) readonly buffer CellStart { uint cell_start[]; };  // (unread: named by walk.glsl)
layout(std430, binding = 11) readonly buffer ScratchX { real4 scratch_x[]; };  // (unread: named by walk.glsl)
#include "neighbour_list.glsl"

// i's position, walls, solve and rate, private to the invocation: set by main, read and summed by `list_entry`
// over the walk
real3 xi;
real3 wall;
real3 inward;
bool density;
real d;

// One entry of i's list (walk.glsl: walk_list hands over each slot): the neighbour j, or its image across the
// walls whose bits are set in `image`, and g = V grad_i W_ik (neighbour_list.glsl); the neighbour's velocity (an
// image's mirrored on the flipped axes) and V (v_i - v_k) . grad_i W_ik, less v_i's part (in d from the start).
void list_entry(uint i, uint slot, inout uvec4 chunk) {
    uint j;
    uint image;
    real3 g = listed_gradient(i, slot, chunk, xi, wall, inward, j, image);
    real3 vk = density ? particle_vstar[j].xyz : particle_v[j].xyz;
    if (image != 0u) {
        vk = real3((image & 1u) != 0u ? -vk.x : vk.x, (image & 2u) != 0u ? -vk.y : vk.y,
                   (image & 4u) != 0u ? -vk.z : vk.z);
    }
    d -= vk.x * g.x + vk.y * g.y + vk.z * g.z;
}
#include "walk.glsl"

shared real s_residual[gl_WorkGroupSize.x];
shared bool s_last;
shared real s_sum[gl_WorkGroupSize.x];
#include "dfsph_check.glsl"

void main() {
    // [1] one invocation per particle (none once the solve has stopped: its dispatch is indirect); every
    //     invocation of the group reaches the barrier, with a residual of 0 past the last particle
    uint i = gl_GlobalInvocationID.x;
    uint lid = gl_LocalInvocationID.x;
    uint solve = D.level;
    real residual = real(0.0);
    if (i < P.n) {
        // [2] the velocity the solve corrects: v (divergence-free), v* = v + dt a (constant density)
        real dt = real(time_state[0].x);
        density = solve == SOLVE_DENSITY;
        xi = particle_x[i].xyz;
        real3 vi = density ? particle_vstar[i].xyz : particle_v[i].xyz;
        // [3] the walls and obstacle faces the images are mirrored across, as in compute_density
        uint mirrored = near_walls(xi, wall);
        mirrored = near_obstacles(xi, mirrored, wall, inward);
        // [4] d_i over the neighbour list (dfsph_factor): every other particle and every image within h
        //     (walk.glsl: walk_list, list_entry above)
        real3 sum_g = particle_gradient_sum[i].xyz;
        d = vi.x * sum_g.x + vi.y * sum_g.y + vi.z * sum_g.z;
        uint count = min(neighbour_count[i], MAX_NEIGHBOURS);
        walk_list(i, count);
        // [5] the residual: compression only. The constant-density one is `precise` (NoContraction), so
        //     that a driver computes it as written, as the mirror does: SPIR-V arithmetic not so marked may be
        //     reassociated and fused, and lavapipe's compiler computed (rho_i / rho_0 - 1) + dt d_i. Near rest
        //     that changed the last bit, so the warm start's test residual > 0 flipped for some particles;
        //     with Wendland C2 (a lattice at rest sums to rho_0) the iteration counts differed from the first
        //     step (issue 30)
        residual = max(d, real(0.0));
        if (density) {
            precise real compression = particle_rho[i] / real(P.rest_density) + dt * d - real(1.0);
            residual = max(compression, real(0.0));
        }
        // [6] store
        particle_residual[i] = residual;
    }
    s_residual[lid] = residual;
    barrier();
    // [7] invocation 0: the group's residuals in order, its part of the solve's error; made visible, then
    //     the group counted as finished: the last one to finish (the count's old value one short of the
    //     groups) runs the check. Which group that is varies; what it computes does not
    uint groups = (P.n + gl_WorkGroupSize.x - 1u) / gl_WorkGroupSize.x;
    if (lid == 0u) {
        real total = real(0.0);
        for (uint k = 0u; k < gl_WorkGroupSize.x; ++k) total += s_residual[k];
        dfsph_partial[gl_WorkGroupID.x] = total;
        memoryBarrierBuffer();
        s_last = atomicAdd(control[CONTROL_FINISHED], 1u) == groups - 1u;
        memoryBarrierBuffer();
    }
    barrier();
    // [8] the last group: the convergence test over every group's sum (dfsph_check.glsl), each
    //     invocation its share, then invocation 0 the error and the stop; the count reset for the next
    if (!s_last) return;
    s_sum[lid] = dfsph_check_share(lid, groups);
    barrier();
    if (lid != 0u) return;
    control[CONTROL_FINISHED] = 0u;
    dfsph_check_decide(solve);
}
