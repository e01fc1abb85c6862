#version 460
// Between two steps of a rank of sphcore.parallel: the rows of its slab each other rank needs for the next step,
// packed for the exchange (sphcore.parallel.Rank.exchange). One invocation per row. Entry e of pick_table is one
// other rank: the rows it may need (those the last sort gave the layers near its slab: decomposition.bands), the
// layers of its slab under the new cuts, and where its rows go. A row whose layer (as count_cells finds it) is in
// that slab is the rank's from now on (a migrant: what a step reads of a particle before writing it); a row
// within the halo's width of the slab (pick_bounds: the slab widened by decomposition.halo_width) is its halo.
// Migrants take slots from the entry's first on, the halo from its last down (atomic counts in pick_count: the
// order of a slot depends on scheduling; the receiver's sort puts every cell in id order whatever its rows).
// The rows go into the sort's scratch buffers, Verlet's half-step velocity into particle_a (gather_particles
// does so too: a step reads neither before writing it).
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
layout(std430, binding = 2) writeonly buffer ParticleA { real4 particle_a[]; };
layout(std430, binding = 35) readonly buffer PickTable { uvec4 pick_table[]; };
layout(std430, binding = 36) readonly buffer PickBounds { vec4 pick_bounds[]; };
layout(std430, binding = 37) buffer PickCount { uint pick_count[]; };

void main() {
    // [1] one invocation per row
    uint i = gl_GlobalInvocationID.x;
    if (i >= P.n) return;
    // [2] the row's layer along the slab axis, as the sort finds it (clamped into the grid), and its coordinate
    uint axis = DIM - 1u;
    real3 x = particle_x[i].xyz;
    uint layer = uint(clamp(cell_of(x)[axis], 0, int(P.grid_dim[axis]) - 1));
    real coordinate = x[axis];
    // [3] each rank the row may go to (pick_table[0].x entries: rows (first, end, slab's first layer, end layer),
    //     then (first slot, slots)), and the slot it takes there
    uint entries = pick_table[0].x;
    for (uint e = 0u; e < entries; e++) {
        uvec4 rows = pick_table[1u + 2u * e];
        if (i < rows.x || i >= rows.y) continue;
        uvec4 slots = pick_table[2u + 2u * e];
        uint k;
        if (layer >= rows.z && layer < rows.w) {
            k = slots.x + atomicAdd(pick_count[2u * e], 1u);
        } else if (coordinate >= real(pick_bounds[e].x) && coordinate < real(pick_bounds[e].y)) {
            k = slots.x + slots.y - 1u - atomicAdd(pick_count[2u * e + 1u], 1u);
        } else {
            continue;
        }
        // [4] the row packed into slot k
        scratch_x[k] = particle_x[i];
        scratch_v[k] = particle_v[i];
        scratch_id[k] = particle_id[i];
        scratch_rho[k] = particle_rho[i];
        if (VERLET) particle_a[k] = particle_vh[i];
    }
}
