#version 460
// Copy position, velocity and id into sorted order (scratch buffers); apply_order copies them
// back. One invocation per sorted position.
// Mirror: sphcore/sph/gather_particles.py (same names, same statement order, same step labels).
#extension GL_GOOGLE_include_directive : require
layout(local_size_x_id = 0) in;
#include "params.glsl"
#include "constants.glsl"
#include "real.glsl"

layout(std430, binding = 0) readonly buffer ParticleX { real4 particle_x[]; };
layout(std430, binding = 1) readonly buffer ParticleV { real4 particle_v[]; };
layout(std430, binding = 5) readonly buffer ParticleId { uint particle_id[]; };
layout(std430, binding = 10) readonly buffer SortedIndex { uint sorted_index[]; };
layout(std430, binding = 11) writeonly buffer ScratchX { real4 scratch_x[]; };
layout(std430, binding = 12) writeonly buffer ScratchV { real4 scratch_v[]; };
layout(std430, binding = 13) writeonly buffer ScratchId { uint scratch_id[]; };
layout(std430, binding = 2) writeonly buffer ParticleA { real4 particle_a[]; };
layout(std430, binding = 19) readonly buffer ParticleVh { real4 particle_vh[]; };

void main() {
    // [1] one invocation per sorted position
    uint k = gl_GlobalInvocationID.x;
    if (k >= P.n) return;
    // [2] fetch the particle that goes there
    uint j = sorted_index[k];
    scratch_x[k] = particle_x[j];
    scratch_v[k] = particle_v[j];
    scratch_id[k] = particle_id[j];
    // [3] Verlet's half-step velocity (integrators.glsl) travels too, with particle_a as its scratch:
    //     nothing reads the acceleration before compute_forces rewrites it
    if (VERLET) particle_a[k] = particle_vh[j];
}
