#version 460
// After a step of a rank of sphcore.parallel whose rows go from GPU to GPU (sphcore.peers: its outbox): the rows
// pick_rows.comp packed into the scratch buffers, written into `sent` as each other rank takes them (place_rows.comp),
// one invocation per row sent (a copy command a buffer's run ran on the copy engine, about a tenth of the memory's
// bandwidth), each entry's (another rank's: pick_table.glsl) after the entries' before it, as packed_rows.glsl lays
// them out: its migrants and halo rows those pick_rows.comp counted (pick_count), in its zones of the scratch buffers.
// Where the rows do not fit in `sent` nothing is written (the host makes room and packs again).
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
layout(std430, binding = 35) readonly buffer PickTable { uvec4 pick_table[]; };
layout(std430, binding = 37) readonly buffer PickCount { uint pick_count[]; };
layout(std430, binding = 38) readonly buffer LayerStart { uint layer_start[]; };
#include "pick_table.glsl"

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
    // [2] its entry: the first whose rows (migrants, then halo) reach past it; its first row sent and word in `sent`,
    //     its zones' first slot and their size; the words of every entry's rows
    uint entries = pick_table[0].x;
    uint e = entries;
    uint at = 0u;
    uint w = 0u;
    uint slot = 0u;
    uint zone = 0u;
    uint rows = 0u;
    uint words = 0u;
    uint base = 0u;
    for (uint f = 0u; f < entries; f++) {
        uint migrants = pick_count[2u * f];
        uint halo = pick_count[2u * f + 1u];
        uint slots = zone_of(entry_rows(f).y);
        if (e == entries && a < rows + migrants + halo) {
            e = f;
            at = rows;
            w = words;
            slot = base;
            zone = slots;
        }
        rows += migrants + halo;
        words += migrant_words(migrants) + halo_words(halo);
        base += 2u * slots;
    }
    if (e == entries || words > uint(sent.length())) return;
    // [3] the runs it goes in: the migrants', else past them the halo's; its slot
    uint j = a - at;
    uint count = pick_count[2u * e];
    bool migrant = j < count;
    uint k = slot + j;
    if (!migrant) {
        w += migrant_words(count);
        j -= count;
        count = pick_count[2u * e + 1u];
        k = slot + zone + j;
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
