#version 460
// After a step of a rank of sphcore.parallel (the step's last stage, or alone before the exchange): the rows of its
// slab each other rank needs for the next step, packed for the exchange (sphcore.parallel.Rank.exchange). One
// invocation per row. Entry e of pick_table is one other rank: the layers whose rows it may need (those the last sort
// gave the layers near its slab: decomposition.bands; their rows from layer_start) and the layers of its slab under the
// next cuts; its slots follow those of the entries before it: two zones of as many as the rows it may need, each
// rounded up to PICK_ALIGN rows (the copies that read them back start on 16 bytes). A row whose layer (as count_cells
// finds it) is in that slab is the rank's from then on (a migrant: what a step reads of a particle before writing it);
// a row within the halo's width of the slab (pick_bounds: the slab widened by decomposition.halo_width) is its halo.
// Migrants take slots from the first zone's first on, the halo from the second's (atomic counts in pick_count: the
// order of a slot depends on scheduling; the receiver's sort puts every cell in id order whatever its rows). The rows
// go into the sort's scratch buffers and scratch_vh (Verlet's half-step velocity), which a step writes before it reads
// them; an entry whose zones end past the rows (P.n) is counted, not written (the host makes room and picks again).
// Mirror: sphcore/sph/pick_rows.py (same names, same statement order, same step labels).
#extension GL_GOOGLE_include_directive : require
layout(local_size_x_id = 0) in;
#include "params.glsl"
#include "constants.glsl"
#include "real.glsl"
#include "cells.glsl"

layout(std430, binding = 0) readonly buffer ParticleX { real4 particle_x[]; };
layout(std430, binding = 1) readonly buffer ParticleV { real4 particle_v[]; };
layout(std430, binding = 3) readonly buffer ParticleRho { real particle_rho[]; };
layout(std430, binding = 5) readonly buffer ParticleId { uint particle_id[]; };
layout(std430, binding = 19) readonly buffer ParticleVh { real4 particle_vh[]; };
layout(std430, binding = 11) writeonly buffer ScratchX { real4 scratch_x[]; };
layout(std430, binding = 12) writeonly buffer ScratchV { real4 scratch_v[]; };
layout(std430, binding = 13) writeonly buffer ScratchId { uint scratch_id[]; };
layout(std430, binding = 18) writeonly buffer ScratchRho { real scratch_rho[]; };
layout(std430, binding = 40) writeonly buffer ScratchVh { real4 scratch_vh[]; };
layout(std430, binding = 35) readonly buffer PickTable { uvec4 pick_table[]; };
layout(std430, binding = 36) readonly buffer PickBounds { vec4 pick_bounds[]; };
layout(std430, binding = 37) buffer PickCount { uint pick_count[]; };
layout(std430, binding = 38) readonly buffer LayerStart { uint layer_start[]; };

const uint PICK_ALIGN = 4u;  // rows: 16 bytes of a 4-byte buffer

// The first row the last sort gave layer `layer` (the rows held past the last layer).
uint row_of(uint layer, uint layers, uint held) { return layer < layers ? layer_start[layer] : held; }

void main() {
    // [1] one invocation per row
    uint i = gl_GlobalInvocationID.x;
    if (i >= P.n) return;
    // [2] the row's layer along the slab axis, as the sort finds it (clamped into the grid), and its coordinate
    uint axis = DIM - 1u;
    real3 x = particle_x[i].xyz;
    uint layer = uint(clamp(cell_of(x)[axis], 0, int(P.grid_dim[axis]) - 1));
    real coordinate = x[axis];
    // [3] each rank the row may go to (pick_table[0]: the entries, the rows held; then an entry's row: the layers
    //     whose rows it may need (first, end), its slab's first layer and end layer), and the slot it takes there
    uint entries = pick_table[0].x;
    uint held = pick_table[0].y;
    uint layers = uint(P.grid_dim[axis]);
    uint base = 0u;
    for (uint e = 0u; e < entries; e++) {
        uvec4 entry = pick_table[1u + e];
        uint first = row_of(entry.x, layers, held);
        uint slots = row_of(entry.y, layers, held) - first;
        uint zone = (slots + PICK_ALIGN - 1u) / PICK_ALIGN * PICK_ALIGN;
        uint slot = base;
        base += 2u * zone;
        if (i < first || i >= first + slots) continue;
        uint k;
        if (layer >= entry.z && layer < entry.w) {
            k = slot + atomicAdd(pick_count[2u * e], 1u);
        } else if (coordinate >= real(pick_bounds[e].x) && coordinate < real(pick_bounds[e].y)) {
            k = slot + zone + atomicAdd(pick_count[2u * e + 1u], 1u);
        } else {
            continue;
        }
        if (slot + 2u * zone > P.n) continue;
        // [4] the row packed into slot k
        scratch_x[k] = particle_x[i];
        scratch_v[k] = particle_v[i];
        scratch_id[k] = particle_id[i];
        scratch_rho[k] = particle_rho[i];
        if (VERLET) scratch_vh[k] = particle_vh[i];
    }
}
