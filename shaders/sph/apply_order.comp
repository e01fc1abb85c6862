#version 460
// Copy the sorted position, velocity and id (and with CONTINUITY the density) back into the particle
// buffers: from here on in the step, particles of one cell are contiguous (cell c holds
// cell_start[c] .. + count).
// One invocation per particle.
// Mirror: sphcore/sph/apply_order.py (same names, same statement order, same step labels).
#extension GL_GOOGLE_include_directive : require
layout(local_size_x_id = 0) in;
#include "params.glsl"
#include "constants.glsl"
#include "real.glsl"

layout(std430, binding = 0) writeonly buffer ParticleX { real4 particle_x[]; };
layout(std430, binding = 1) writeonly buffer ParticleV { real4 particle_v[]; };
layout(std430, binding = 5) writeonly buffer ParticleId { uint particle_id[]; };
layout(std430, binding = 11) readonly buffer ScratchX { real4 scratch_x[]; };
layout(std430, binding = 12) readonly buffer ScratchV { real4 scratch_v[]; };
layout(std430, binding = 13) readonly buffer ScratchId { uint scratch_id[]; };
layout(std430, binding = 3) writeonly buffer ParticleRho { real particle_rho[]; };
layout(std430, binding = 18) readonly buffer ScratchRho { real scratch_rho[]; };
layout(std430, binding = 2) readonly buffer ParticleA { real4 particle_a[]; };
layout(std430, binding = 19) writeonly buffer ParticleVh { real4 particle_vh[]; };
layout(std430, binding = 27) writeonly buffer ParticleKappa { real particle_kappa[]; };

void main() {
    // [1] one invocation per particle
    uint k = gl_GlobalInvocationID.x;
    if (k >= P.n) return;
    // [2] copy back
    particle_x[k] = scratch_x[k];
    particle_v[k] = scratch_v[k];
    particle_id[k] = scratch_id[k];
    if (CONTINUITY) particle_rho[k] = scratch_rho[k];
    // [3] Verlet's half-step velocity, back from its scratch (gather_particles.comp)
    if (VERLET) particle_vh[k] = particle_a[k];
    // [4] DFSPH's warm start, back from its scratch (gather_particles.comp)
    if (DFSPH) particle_kappa[k] = scratch_rho[k];
}
