#version 460
// Adaptive time step (time.dt = "adaptive", ADAPTIVE_DT), first of two stages: each work group's
// largest |v|^2 and |a|^2 (after compute_forces: the velocity and acceleration the step integrates),
// reduced in shared memory to one partial per group in dt_partial; choose_dt.comp reduces the
// partials and sets the step's dt on the device. A maximum is exact in any order, so the result
// depends neither on the reduction tree nor on the GPU's schedule: both backends get the same bits.
// One invocation per particle; the bodies' wall particles (BODIES) hold 0: they do not move. On a rank of
// sphcore.parallel the particles of its slab only (P.owned_first, owned_end: the others' are a halo).
// Mirror: sphcore/sph/reduce_dt.py (same names, same statement order, same step labels; one local
// loop per phase between barriers).
#extension GL_GOOGLE_include_directive : require
layout(local_size_x_id = 0) in;
#include "params.glsl"
#include "constants.glsl"
#include "real.glsl"

layout(std430, binding = 1) readonly buffer ParticleV { real4 particle_v[]; };
layout(std430, binding = 2) readonly buffer ParticleA { real4 particle_a[]; };
layout(std430, binding = 5) readonly buffer ParticleId { uint particle_id[]; };  // BODIES: a wall particle's id
layout(std430, binding = 9) readonly buffer CellStart { uint cell_start[]; };  // (a rank's slab's rows)
layout(std430, binding = 21) writeonly buffer DtPartial { real dt_partial[]; };  // (|v|^2, |a|^2) per group

shared real s_v2[gl_WorkGroupSize.x];
shared real s_a2[gl_WorkGroupSize.x];

void main() {
    // [1] own |v|^2 and |a|^2; an invocation past the last particle, or on a rank past the rows the sort gave
    //     its slab's cells, holds 0 (all reach the barriers)
    uint i = gl_GlobalInvocationID.x;
    uint lid = gl_LocalInvocationID.x;
    uint first = 0u;
    uint end = P.n;
    if (P.owned_end > 0u) {
        first = cell_start[P.owned_first];
        end = P.owned_end < P.cell_total ? cell_start[P.owned_end] : P.n;
    }
    real v2 = real(0.0);
    real a2 = real(0.0);
    if (i >= first && i < end && !(BODIES && particle_id[i] >= P.fluid_count)) {
        real3 v = particle_v[i].xyz;
        real3 a = particle_a[i].xyz;
        v2 = v.x * v.x + v.y * v.y + v.z * v.z;
        a2 = a.x * a.x + a.y * a.y + a.z * a.z;
    }
    s_v2[lid] = v2;
    s_a2[lid] = a2;
    barrier();
    // [2] tree: at stride s, each invocation at a multiple of 2 s takes the larger of its own and the one s above
    for (uint stride = 1u; stride < gl_WorkGroupSize.x; stride *= 2u) {
        if (lid % (2u * stride) == 0u && lid + stride < gl_WorkGroupSize.x) {
            s_v2[lid] = max(s_v2[lid], s_v2[lid + stride]);
            s_a2[lid] = max(s_a2[lid], s_a2[lid + stride]);
        }
        barrier();
    }
    // [3] the group's partial
    if (lid == 0u) {
        dt_partial[2u * gl_WorkGroupID.x] = s_v2[0];
        dt_partial[2u * gl_WorkGroupID.x + 1u] = s_a2[0];
    }
}
