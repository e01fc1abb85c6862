#version 460
// Before a step of a rank of sphcore.parallel whose rows came from GPU to GPU (sphcore.peers: its inbox): the rows
// received from the other ranks written over the old halo's rows, one invocation per received row (the step's first
// stage; a copy command a buffer's run ran on the copy engine, about a tenth of the memory's bandwidth). `received`
// holds each sender's rows as Rank.swap_peers pulled them (packed_rows.glsl). place_table[0]: the senders, the first
// and the end of the rows the rank owns, the rows received; place_table[1 + s]: sender s's first word in `received`,
// its migrants and halo rows. A received row goes below the owned rows while there is room there, after them from then
// on.
// Mirror: sphcore/sph/place_rows.py (same names, same statement order, same step labels).
#extension GL_GOOGLE_include_directive : require
layout(local_size_x_id = 0) in;
#include "params.glsl"
#include "constants.glsl"
#include "real.glsl"
#include "packed_rows.glsl"

layout(std430, binding = 0) writeonly buffer ParticleX { real4 particle_x[]; };
layout(std430, binding = 1) writeonly buffer ParticleV { real4 particle_v[]; };
layout(std430, binding = 3) writeonly buffer ParticleRho { real particle_rho[]; };
layout(std430, binding = 5) writeonly buffer ParticleId { uint particle_id[]; };
layout(std430, binding = 19) writeonly buffer ParticleVh { real4 particle_vh[]; };
layout(std430, binding = 41) readonly buffer Received { uint received[]; };
layout(std430, binding = 42) readonly buffer PlaceTable { uvec4 place_table[]; };

#ifdef SPHCORE_FLOAT64
real real_at(uint w) { return packDouble2x32(uvec2(received[w], received[w + 1u])); }
#else
real real_at(uint w) { return uintBitsToFloat(received[w]); }
#endif

real4 real4_at(uint w) {
    return real4(real_at(w), real_at(w + REAL_WORDS), real_at(w + 2u * REAL_WORDS), real_at(w + 3u * REAL_WORDS));
}

void main() {
    // [1] one invocation per received row
    uint a = gl_GlobalInvocationID.x;
    uvec4 head = place_table[0];
    if (a >= head.w) return;
    // [2] its sender: the first whose rows (migrants, then halo) reach past it
    uint s = 0u;
    uint at = 0u;
    while (a >= at + place_table[1u + s].y + place_table[1u + s].z) {
        at += place_table[1u + s].y + place_table[1u + s].z;
        s++;
    }
    uvec4 sender = place_table[1u + s];
    // [3] the runs it is in: the migrants', else past them the halo's
    uint j = a - at;
    uint w = sender.x;
    uint count = sender.y;
    bool migrant = j < sender.y;
    if (!migrant) {
        w += migrant_words(sender.y);
        j -= sender.y;
        count = sender.z;
    }
    // [4] the row it replaces: below the owned rows, else after them
    uint row = a < head.y ? a : a + head.z - head.y;
    // [5] store
    particle_x[row] = real4_at(w + j * 4u * REAL_WORDS);
    w += run_words(count, 4u * REAL_WORDS);
    particle_v[row] = real4_at(w + j * 4u * REAL_WORDS);
    w += run_words(count, 4u * REAL_WORDS);
    particle_rho[row] = real_at(w + j * REAL_WORDS);
    w += run_words(count, REAL_WORDS);
    particle_id[row] = received[w + j];
    w += run_words(count, 1u);
    if (VERLET && migrant) particle_vh[row] = real4_at(w + j * 4u * REAL_WORDS);
}
