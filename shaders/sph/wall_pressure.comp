#version 460
// The bodies' wall particles (BODIES: ids P.fluid_count and up), Adami, Hu & Adams 2012 ("A generalized wall
// boundary condition for smoothed particle hydrodynamics", J. Comput. Phys. 231), one invocation per particle,
// after the fluid's density and pressure (compute_density, integrate_density), before compute_forces:
//     p_w = (sum_f p_f W_wf + (g - a_w) . sum_f rho_f r_wf W_wf) / sum_f W_wf          (Adami's eq. 27)
//     v_w = 2 v_body - sum_f v_f W_wf / sum_f W_wf                                  (eq. 22; no slip only)
// over the fluid particles f (and their images across the box walls) within h of the wall particle w,
// r_wf = x_w - x_f. The bodies are fixed (v_body = a_w = 0). The density that goes with p_w is the
// equation of state's inverse (wall_density), for the pressure term's p_w / rho_w^2. A wall particle with no
// fluid within h has p_w = 0, rho_w = rho_0, v_w = 0. With summation density p_w is clamped at 0, as the fluid's
// (equation_of_state.glsl). compute_forces lets the fluid feel the wall particles through the pressure term
// (and with NO_SLIP the viscous term, with v_w), and computes the force the fluid exerts on each of them.
// Fluid particles return at once.
// Mirror: sphcore/sph/wall_pressure.py (same names, same statement order, same step labels).
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

layout(std430, binding = 0) readonly buffer ParticleX { real4 particle_x[]; };
layout(std430, binding = 1) buffer ParticleV { real4 particle_v[]; };  // the fluid's read, the walls' written
layout(std430, binding = 3) buffer ParticleRho { real particle_rho[]; };
layout(std430, binding = 4) buffer ParticleP { real particle_p[]; };
layout(std430, binding = 5) readonly buffer ParticleId { uint particle_id[]; };
layout(std430, binding = 8) readonly buffer CellPyramid { uint cell_pyramid[]; };
layout(std430, binding = 9) readonly buffer CellStart { uint cell_start[]; };
layout(std430, binding = 11) readonly buffer ScratchX { real4 scratch_x[]; };  // LIST_SKIN: x at the list's build
layout(std430, binding = 29) readonly buffer Neighbours { uint neighbours[]; };
layout(std430, binding = 29) readonly buffer NeighbourChunks { uvec4 neighbour_chunks[]; };  // (the same, by chunks)
layout(std430, binding = 30) readonly buffer NeighbourCount { uint neighbour_count[]; };
layout(std430, binding = 31) readonly buffer NeighbourGradients { real4 neighbour_gradients[]; };  // (unread: named by
                                                                                           // neighbour_list.glsl)
#include "neighbour_list.glsl"

// the wall particle's sums over the fluid, private to the invocation: summed by `pair` over the walk
real sum_w;
real sum_p;
real3 sum_rho_r;
real3 sum_v;

// One pair (walk.glsl): a fluid particle j, or its image, at r = x_w - x_k; other wall particles are skipped.
void pair(uint i, uint j, uint image, real3 r, real r2, real3 inward) {
    if (particle_id[j] >= P.fluid_count) return;
    real w = kernel_w(r2);
    sum_w += w;
    sum_p += particle_p[j] * w;
    sum_rho_r += particle_rho[j] * w * r;
    if (NO_SLIP) sum_v += image_velocity(particle_v[j].xyz, image) * w;
}
#include "walk.glsl"

// The density of pressure p: the equation of state's inverse (equation_of_state.glsl), linear:
// rho_0 + p / k; Tait: rho_0 y^(1/7), y = 1 + p / B, by four Newton steps on x^7 = y from 1 + (y - 1) / 7
// (multiplications only: the same bits on every device); y is kept at 1/2 or more (p >= -B / 2).
real wall_density(real p) {
    if (!TAIT) return P.rest_density + p / P.stiffness;
    real y = max(real(1.0) + p / P.stiffness, real(0.5));
    real x = real(1.0) + (y - real(1.0)) / real(7.0);
    for (uint k = 0u; k < 4u; ++k) {
        real x2 = x * x;
        real x6 = x2 * x2 * x2;
        x -= (x6 * x - y) / (real(7.0) * x6);
    }
    return P.rest_density * x;
}

void main() {
    // [1] one invocation per wall particle; the grid is rounded up to whole work groups
    uint i = gl_GlobalInvocationID.x;
    if (i >= P.n || particle_id[i] < P.fluid_count) return;
    // [2] the sums over the fluid and its images within h (walk.glsl)
    real3 xi = particle_x[i].xyz;
    sum_w = real(0.0);
    sum_p = real(0.0);
    sum_rho_r = real3(0.0);
    sum_v = real3(0.0);
    walk_neighbours(i, xi);
    // [3] Adami's pressure (gravity with GRAVITY; a fixed wall has no acceleration) and velocity
    real p = real(0.0);
    real3 v = real3(0.0);
    if (sum_w > real(0.0)) {
        real3 g = GRAVITY ? real3(P.gravity) : real3(0.0);
        p = (sum_p + (g.x * sum_rho_r.x + g.y * sum_rho_r.y + g.z * sum_rho_r.z)) / sum_w;
        if (NO_SLIP) v = -sum_v / sum_w;
    }
    if (!CONTINUITY) p = max(p, real(0.0));
    // [4] store
    particle_p[i] = p;
    particle_rho[i] = wall_density(p);
    particle_v[i] = real4(v, 0.0);
}
