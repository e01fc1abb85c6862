#version 460
// One Jacobi update of DFSPH's solve D.level (dfsph.glsl), one invocation per particle: with the
// stiffness s_j = alpha_j r_j (divergence-free, [1/s]) or alpha_j r_j / dt^2 (constant density, [1/s^2])
// of every particle from the last dfsph_residual, the change -sum_j V (s_i + s_j) grad W_ij over the
// neighbour list (walk.glsl: walk_list; dfsph_factor: the neighbours and their wall and obstacle images; an image carries its
// particle's s) is added to the velocity (divergence-free) or to the acceleration the step integrates
// (constant density, which also accumulates the pressure p_i += s_i rho_i^2 / rho_0: the state equation's
// m p_i / rho_i^2 = V s_i, and keeps v* = v + dt a in scratch_v for the next residual: dfsph_predict).
// Every invocation reads only the residuals and writes only its own particle: a Jacobi sweep.
// Dispatched indirectly: no work groups once the solve has stopped; invocation 0 counts the update.
// Mirror: sphcore/sph/dfsph_velocity.py (same names, same statement order, same step labels).
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
layout(std430, binding = 1) buffer ParticleV { real4 particle_v[]; };
layout(std430, binding = 2) buffer ParticleA { real4 particle_a[]; };
layout(std430, binding = 3) readonly buffer ParticleRho { real particle_rho[]; };
layout(std430, binding = 4) buffer ParticleP { real particle_p[]; };
layout(std430, binding = 12) writeonly buffer ScratchV { real4 particle_vstar[]; };
layout(std430, binding = 20) readonly buffer TimeState { vec4 time_state[]; };
layout(std430, binding = 22) readonly buffer ParticleAlpha { real particle_alpha[]; };
layout(std430, binding = 23) readonly buffer ParticleResidual { real particle_residual[]; };
layout(std430, binding = 24) buffer Control { uint control[]; };
layout(std430, binding = 27) buffer ParticleKappa { real particle_kappa[]; };
layout(std430, binding = 29) readonly buffer Neighbours { uint neighbours[]; };
layout(std430, binding = 29) readonly buffer NeighbourChunks { uvec4 neighbour_chunks[]; };  // (the same, by chunks)
layout(std430, binding = 30) readonly buffer NeighbourCount { uint neighbour_count[]; };
layout(std430, binding = 31) readonly buffer NeighbourGradients { real4 neighbour_gradients[]; };
layout(std430, binding = 8) readonly buffer CellPyramid { uint cell_pyramid[]; };  // (unread: named by walk.glsl)
layout(std430, binding = 9) readonly buffer CellStart { uint cell_start[]; };  // (unread: named by walk.glsl)
layout(std430, binding = 11) readonly buffer ScratchX { real4 scratch_x[]; };  // (unread: named by walk.glsl)
#include "neighbour_list.glsl"

// i's position, walls, stiffness and change, private to the invocation: set by main, read and summed by
// `list_entry` over the walk
real3 xi;
real3 wall;
real3 inward;
bool warm;
real scale;
real si;
real3 change;

// One entry of i's list (walk.glsl: walk_list hands over each slot): the neighbour j (or its image: the same s_j)
// and g = V grad_i W_ij (neighbour_list.glsl); -V (s_i + s_j) grad_i W_ij: away from a compressed neighbourhood.
void list_entry(uint i, uint slot, inout uvec4 chunk) {
    uint j;
    uint image;
    real3 g = listed_gradient(i, slot, chunk, xi, wall, inward, j, image);
    real sj = scale * particle_alpha[j] * particle_residual[j];
    if (warm) {
        real kappa_j = particle_kappa[j];  // (read before the test: a select, not a branch that mispredicts)
        sj = particle_residual[j] > real(0.0) ? kappa_j : real(0.0);
    }
    real t = si + sj;
    change -= t * g;
}
#include "walk.glsl"

void main() {
    // [1] one invocation per particle (none once the solve has stopped: its dispatch is indirect);
    //     invocation 0 counts the update
    uint i = gl_GlobalInvocationID.x;
    if (i >= P.n) return;
    uint solve = D.level;
    warm = solve == SOLVE_WARM_START;  // the warm start: always, and not counted
    if (!warm && i == 0u) control[CONTROL_ITERATIONS + solve] += 1u;
    // [2] the stiffness scale: 1 (divergence-free), 1 / dt^2 (constant density); own stiffness s_i (warm
    //     start: the stiffness sum, particle_kappa, where the particle is compressed: residual > 0)
    real dt = real(time_state[0].x);
    scale = solve == SOLVE_DIVERGENCE ? real(1.0) : real(1.0) / (dt * dt);
    si = scale * particle_alpha[i] * particle_residual[i];
    if (warm) si = particle_residual[i] > real(0.0) ? particle_kappa[i] : real(0.0);
    xi = particle_x[i].xyz;
    // [3] the walls and obstacle faces the images are mirrored across, as in compute_density
    uint mirrored = near_walls(xi, wall);
    mirrored = near_obstacles(xi, mirrored, wall, inward);
    // [4] the change over the neighbour list (dfsph_factor): every other particle and every image within h
    //     (walk.glsl: walk_list, list_entry above)
    change = real3(0.0);
    uint count = min(neighbour_count[i], MAX_NEIGHBOURS);
    walk_list(i, count);
    // [5] store: the velocity (divergence-free) or the acceleration, the stiffness sum and the pressure
    //     (constant density; only the warm start reads the sum of others, and it writes none)
    if (solve == SOLVE_DIVERGENCE) {
        particle_v[i] = real4(particle_v[i].xyz + change, 0.0);
    } else {
        real3 a = particle_a[i].xyz + change;
        particle_a[i] = real4(a, 0.0);
        particle_vstar[i] = real4(particle_v[i].xyz + dt * a, 0.0);
        real rhoi = particle_rho[i];
        real p = si * rhoi * rhoi / real(P.rest_density);
        if (!warm) p += particle_p[i];
        particle_p[i] = p;
        if (!warm) particle_kappa[i] = p * real(P.rest_density) / (rhoi * rhoi);
    }
}
