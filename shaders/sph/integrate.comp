#version 460
// Time step (integrate_row.glsl: integrators.glsl's symplectic Euler or kick-drift-kick Verlet leapfrog, box walls
// and obstacles), one invocation per particle. dt is P.dt, or with ADAPTIVE_DT the one choose_dt.comp wrote
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
#include "integrate_row.glsl"

void main() {
    // [1] one invocation per fluid particle; the grid is rounded up to whole work groups
    uint i = gl_GlobalInvocationID.x;
    if (i >= P.n || (BODIES && particle_id[i] >= P.fluid_count)) return;
    // [2] the step's dt: P.dt, or the device's (time_state: dt, the last step's dt, time; choose_dt.comp)
    float dt = ADAPTIVE_DT ? time_state[0].x : P.dt;
    float dt_prev = VERLET ? time_state[0].y : 0.0;
    // [3] the step (integrate_row.glsl), stored: the position, the velocity the integrator stores and Verlet's half
    //     step's
    real3 x;
    real3 v;
    real3 vh;
    integrated(i, dt, dt_prev, SHIFTING > 0u ? particle_shift[i] : real4(0.0), x, v, vh);
    particle_x[i] = real4(x, 0.0);
    particle_v[i] = real4(v, 0.0);
    if (VERLET) particle_vh[i] = real4(vh, 0.0);
    // [4] reused lists: the next step builds them where this particle has moved too far since the last build
    //     (every particle that has writes the same 1)
    if (LIST_SKIN > 0u) {
        real3 moved = x - scratch_x[i].xyz;
        if (moved.x * moved.x + moved.y * moved.y + moved.z * moved.z > moved_limit2()) control[CONTROL_REBUILD] = 1u;
    }
}
