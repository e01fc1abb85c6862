#version 460
// DFSPH: the velocity v* = v + dt a that the constant-density solve corrects (dfsph.glsl), one invocation
// per particle, once this step's dt is known (after choose_dt) and before the solve's first residual.
// It lives in scratch_v, which the sort needs only before compute_density: dfsph_residual reads each
// neighbour's v* there (one vector a pair, not v and a), and dfsph_velocity keeps it up to date with
// every update of the acceleration. The same sum as the integrator's, so the same bits.
// Mirror: sphcore/sph/dfsph_predict.py (same names, same statement order, same step labels).
#extension GL_GOOGLE_include_directive : require
layout(local_size_x_id = 0) in;
#include "params.glsl"
#include "constants.glsl"
#include "real.glsl"

layout(std430, binding = 1) readonly buffer ParticleV { real4 particle_v[]; };
layout(std430, binding = 2) readonly buffer ParticleA { real4 particle_a[]; };
layout(std430, binding = 12) writeonly buffer ScratchV { real4 particle_vstar[]; };
layout(std430, binding = 20) readonly buffer TimeState { vec4 time_state[]; };

void main() {
    // [1] one invocation per particle
    uint i = gl_GlobalInvocationID.x;
    if (i >= P.n) return;
    // [2] v* = v + dt a with this step's dt
    real dt = real(time_state[0].x);
    particle_vstar[i] = real4(particle_v[i].xyz + dt * particle_a[i].xyz, 0.0);
}
