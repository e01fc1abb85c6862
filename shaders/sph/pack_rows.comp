#version 460
// After a step of a rank of sphcore.parallel whose rows go from GPU to GPU (sphcore.peers: its outbox): the rows
// pick_rows.comp packed into the scratch buffers, written into `sent` as each other rank takes them (place_rows.comp),
// one invocation per row sent (a copy command a buffer's run ran on the copy engine, about a tenth of the memory's
// bandwidth), each entry's (another rank's) as packed_rows.glsl lays them out. pack_table[0]: the entries, the rows
// sent; pack_table[1 + 2e]: entry e's first word in `sent`, its migrants and halo rows; pack_table[2 + 2e]: the first
// slot of its migrants and of its halo in the scratch buffers (pick_rows.comp's zones).
// Mirror: sphcore/sph/pack_rows.py (same names, same statement order, same step labels).
#extension GL_GOOGLE_include_directive : require
layout(local_size_x_id = 0) in;
#include "params.glsl"
#include "constants.glsl"
#include "real.glsl"
#include "packed_rows.glsl"

layout(std430, binding = 11) readonly buffer ScratchX { real4 scratch_x[]; };
layout(std430, binding = 12) readonly buffer ScratchV { real4 scratch_v[]; };
layout(std430, binding = 13) readonly buffer ScratchId { uint scratch_id[]; };
layout(std430, binding = 18) readonly buffer ScratchRho { real scratch_rho[]; };
layout(std430, binding = 40) readonly buffer ScratchVh { real4 scratch_vh[]; };
layout(std430, binding = 43) writeonly buffer Sent { uint sent[]; };
layout(std430, binding = 44) readonly buffer PackTable { uvec4 pack_table[]; };

#ifdef SPHCORE_FLOAT64
void put_real(uint w, real value) {
    uvec2 words = unpackDouble2x32(value);
    sent[w] = words.x;
    sent[w + 1u] = words.y;
}
#else
void put_real(uint w, real value) { sent[w] = floatBitsToUint(value); }
#endif

void put_real4(uint w, real4 value) {
    for (uint c = 0u; c < 4u; c++) put_real(w + c * REAL_WORDS, value[c]);
}

void main() {
    // [1] one invocation per row sent
    uint a = gl_GlobalInvocationID.x;
    if (a >= pack_table[0].y) return;
    // [2] its entry: the first whose rows (migrants, then halo) reach past it
    uint e = 0u;
    uint at = 0u;
    while (a >= at + pack_table[1u + 2u * e].y + pack_table[1u + 2u * e].z) {
        at += pack_table[1u + 2u * e].y + pack_table[1u + 2u * e].z;
        e++;
    }
    uvec4 entry = pack_table[1u + 2u * e];
    uvec4 slots = pack_table[2u + 2u * e];
    // [3] the runs it goes in: the migrants', else past them the halo's; its slot
    uint j = a - at;
    uint w = entry.x;
    uint count = entry.y;
    bool migrant = j < entry.y;
    uint k = slots.x + j;
    if (!migrant) {
        w += migrant_words(entry.y);
        j -= entry.y;
        count = entry.z;
        k = slots.y + j;
    }
    // [4] store
    put_real4(w + j * 4u * REAL_WORDS, scratch_x[k]);
    w += run_words(count, 4u * REAL_WORDS);
    put_real4(w + j * 4u * REAL_WORDS, scratch_v[k]);
    w += run_words(count, 4u * REAL_WORDS);
    put_real(w + j * REAL_WORDS, scratch_rho[k]);
    w += run_words(count, REAL_WORDS);
    sent[w + j] = scratch_id[k];
    w += run_words(count, 1u);
    if (VERLET && migrant) put_real4(w + j * 4u * REAL_WORDS, scratch_vh[k]);
}
