#version 460
// Copy position, velocity and id into sorted order (scratch buffers); apply_order copies them
// back. With continuity density (CONTINUITY) the density is state and travels too. One invocation
// per sorted position.
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
layout(std430, binding = 3) readonly buffer ParticleRho { real particle_rho[]; };
layout(std430, binding = 18) writeonly buffer ScratchRho { real scratch_rho[]; };
layout(std430, binding = 2) writeonly buffer ParticleA { real4 particle_a[]; };
layout(std430, binding = 19) readonly buffer ParticleVh { real4 particle_vh[]; };
layout(std430, binding = 27) readonly buffer ParticleKappa { real particle_kappa[]; };

void main() {
    // [1] one invocation per sorted position
    uint k = gl_GlobalInvocationID.x;
    if (k >= P.n) return;
    // [2] fetch the particle that goes there
    uint j = sorted_index[k];
    scratch_x[k] = particle_x[j];
    scratch_v[k] = particle_v[j];
    scratch_id[k] = particle_id[j];
    if (CONTINUITY) scratch_rho[k] = particle_rho[j];
    // [3] Verlet's half-step velocity (integrators.glsl) travels too, with particle_a as its scratch:
    //     nothing reads the acceleration before compute_forces rewrites it
    if (VERLET) particle_a[k] = particle_vh[j];
    // [4] DFSPH's warm start (dfsph.glsl) travels too, with scratch_rho as its scratch (no continuity density)
    if (DFSPH) scratch_rho[k] = particle_kappa[j];
}
