#version 460
// Time step (integrators.glsl: symplectic Euler or the kick-drift-kick Verlet leapfrog), box walls and
// obstacles, one invocation per particle. dt is P.dt, or with ADAPTIVE_DT the one choose_dt.comp wrote
// into time_state on the device this step (no readback). Reused lists (LIST_SKIN): a particle that has moved
// too far from where it was at the lists' build asks for the next build (cells.glsl: moved_limit2). With shifting
// (SHIFTING) the drift is followed by the particle's shift (shifting.glsl), before the walls. The bodies' wall
// particles (BODIES) are fixed: left as they are.
// Mirror: sphcore/sph/integrate.py (same names, same statement order, same step labels).
#extension GL_GOOGLE_include_directive : require
layout(local_size_x_id = 0) in;
#include "params.glsl"
#include "constants.glsl"
#include "real.glsl"
#include "integrators.glsl"
#include "cells.glsl"
#include "dfsph.glsl"
#include "kernels.glsl"
#include "shifting.glsl"

layout(std430, binding = 0) buffer ParticleX { real4 particle_x[]; };
layout(std430, binding = 1) buffer ParticleV { real4 particle_v[]; };
layout(std430, binding = 2) readonly buffer ParticleA { real4 particle_a[]; };
layout(std430, binding = 12) readonly buffer ParticleShift { real4 particle_shift[]; };  // SHIFTING: scratch_v,
                                                                                             // compute_forces' sums
layout(std430, binding = 11) readonly buffer ScratchX { real4 scratch_x[]; };  // LIST_SKIN: x at the list's build
layout(std430, binding = 16) readonly buffer ObstacleBox { vec4 obstacle_box[]; };
layout(std430, binding = 19) buffer ParticleVh { real4 particle_vh[]; };
layout(std430, binding = 20) readonly buffer TimeState { vec4 time_state[]; };
layout(std430, binding = 24) buffer Control { uint control[]; };  // LIST_SKIN: CONTROL_REBUILD
layout(std430, binding = 5) readonly buffer ParticleId { uint particle_id[]; };  // BODIES: a wall particle's id

void main() {
    // [1] one invocation per fluid particle; the grid is rounded up to whole work groups
    uint i = gl_GlobalInvocationID.x;
    if (i >= P.n || (BODIES && particle_id[i] >= P.fluid_count)) return;
    // [2] the step's dt: P.dt, or the device's (time_state: dt, the last step's dt, time; choose_dt.comp)
    float dt = ADAPTIVE_DT ? time_state[0].x : P.dt;
    float dt_prev = VERLET ? time_state[0].y : 0.0;
    // [3] kick and drift (integrators.glsl): v is the velocity that moves the particle over the step
    real3 a = particle_a[i].xyz;
    real3 v = drift_velocity(particle_v[i].xyz, particle_vh[i].xyz, a, dt, dt_prev);
    real3 x = particle_x[i].xyz + dt * v;
    if (SHIFTING > 0u) x += shift_of(particle_shift[i], v, dt);  // (shifting.glsl: Lind et al. 2012)
    // [4] walls: each axis is tested on its own (no else-if), so a particle past a corner is
    //     put back on every wall it crossed in the same step. Clamp the position; an outward
    //     normal speed is reversed and scaled by the restitution, an inward one is kept.
    if (WALLS) {
        if (x.x < P.box_min.x) { x.x = P.box_min.x; v.x = max(v.x, -P.restitution * v.x); }
        if (x.x > P.box_max.x) { x.x = P.box_max.x; v.x = min(v.x, -P.restitution * v.x); }
        if (x.y < P.box_min.y) { x.y = P.box_min.y; v.y = max(v.y, -P.restitution * v.y); }
        if (x.y > P.box_max.y) { x.y = P.box_max.y; v.y = min(v.y, -P.restitution * v.y); }
        if (DIM == 3u && x.z < P.box_min.z) { x.z = P.box_min.z; v.z = max(v.z, -P.restitution * v.z); }
        if (DIM == 3u && x.z > P.box_max.z) { x.z = P.box_max.z; v.z = min(v.z, -P.restitution * v.z); }
    }
    // [5] obstacles (shaders/sph/obstacles.glsl): a particle that ended the step inside a box is put
    //     back onto the box's face nearest to it, its normal speed there treated as at a wall. The
    //     images across the faces keep particles off them; this catches the rare one that got in.
    for (uint o = 0u; o < OBSTACLES; ++o) {
        real3 lo = real3(obstacle_box[2u * o].xyz);
        real3 hi = real3(obstacle_box[2u * o + 1u].xyz);
        real3 depth = min(x - lo, hi - x);  // > 0: inside the box on that axis, that far from a face
        if (depth.x <= real(0.0) || depth.y <= real(0.0) || (DIM == 3u && depth.z <= real(0.0))) continue;
        if (depth.x <= depth.y && (DIM == 2u || depth.x <= depth.z)) {
            bool lower = x.x - lo.x <= hi.x - x.x;
            x.x = lower ? lo.x : hi.x;
            v.x = lower ? min(v.x, -P.restitution * v.x) : max(v.x, -P.restitution * v.x);
        } else if (DIM == 2u || depth.y <= depth.z) {
            bool lower = x.y - lo.y <= hi.y - x.y;
            x.y = lower ? lo.y : hi.y;
            v.y = lower ? min(v.y, -P.restitution * v.y) : max(v.y, -P.restitution * v.y);
        } else {
            bool lower = x.z - lo.z <= hi.z - x.z;
            x.z = lower ? lo.z : hi.z;
            v.z = lower ? min(v.z, -P.restitution * v.z) : max(v.z, -P.restitution * v.z);
        }
    }
    // [6] store: the position, the velocity the integrator stores (integrators.glsl) and Verlet's half step's
    particle_x[i] = real4(x, 0.0);
    particle_v[i] = real4(stored_velocity(v, a, dt), 0.0);
    if (VERLET) particle_vh[i] = real4(v, 0.0);
    // [7] reused lists: the next step builds them where this particle has moved too far since the last build
    //     (every particle that has writes the same 1)
    if (LIST_SKIN > 0u) {
        real3 moved = x - scratch_x[i].xyz;
        if (moved.x * moved.x + moved.y * moved.y + moved.z * moved.z > moved_limit2()) control[CONTROL_REBUILD] = 1u;
    }
}
