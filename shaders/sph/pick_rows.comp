#version 460
// After a step of a rank of sphcore.parallel (the step's last stage, or alone before the exchange; D.level 1: before
// integrate, where the exchange overlaps the step's end): the rows of its slab each other rank needs for the next
// step, packed for the exchange (sphcore.parallel.Rank.exchange). Entry e of pick_table is one
// other rank (pick_table.glsl): the layers whose rows it may need (those the step's sort gave the layers near its
// slab: decomposition.bands; pick_groups.comp wrote them in band_rows) and the layers of its slab under the next cuts;
// one invocation takes one entry's row (a row two entries read, one for each); its slots follow those of the entries
// before it: two zones of as many as the rows it may need, each rounded up to PICK_ALIGN rows (the copies that read
// them back start on 16 bytes). A row whose layer (as count_cells finds it) is in that slab is the rank's from then on
// (a migrant: what a step reads of a particle before writing it); a row within the halo's width of the slab
// (pick_bounds: the slab widened by decomposition.halo_width) is its halo. At D.level 1 a row is taken as integrate
// will store it (integrate_row.glsl; no shifting: its sums are in scratch_v): at a fixed dt P.dt, before choose_dt
// (time_state's dt is the last step's), or with an adaptive dt after choose_dt (time_state: the step's, the last's).
// Migrants take slots from the first zone's first on, the halo from the second's (atomic counts in pick_count: the
// order of a slot depends on scheduling; the receiver's sort puts every cell in id order whatever its rows). The
// rows go into the sort's scratch buffers and scratch_vh (Verlet's half-step velocity), which a step writes before
// it reads them; an entry whose zones end past the rows (P.n) is counted, not written (the host makes room and
// picks again).
// Mirror: sphcore/sph/pick_rows.py (same names, same statement order, same step labels).
#extension GL_GOOGLE_include_directive : require
layout(local_size_x_id = 0) in;
#include "params.glsl"
#include "constants.glsl"
#include "real.glsl"
#include "integrators.glsl"
#include "cells.glsl"
#include "kernels.glsl"
#include "shifting.glsl"

layout(std430, binding = 0) readonly buffer ParticleX { real4 particle_x[]; };
layout(std430, binding = 1) readonly buffer ParticleV { real4 particle_v[]; };
layout(std430, binding = 2) readonly buffer ParticleA { real4 particle_a[]; };
layout(std430, binding = 3) readonly buffer ParticleRho { real particle_rho[]; };
layout(std430, binding = 5) readonly buffer ParticleId { uint particle_id[]; };
layout(std430, binding = 19) readonly buffer ParticleVh { real4 particle_vh[]; };
layout(std430, binding = 16) readonly buffer ObstacleBox { vec4 obstacle_box[]; };
layout(std430, binding = 20) readonly buffer TimeState { vec4 time_state[]; };
layout(std430, binding = 11) writeonly buffer ScratchX { real4 scratch_x[]; };
layout(std430, binding = 12) writeonly buffer ScratchV { real4 scratch_v[]; };
layout(std430, binding = 13) writeonly buffer ScratchId { uint scratch_id[]; };
layout(std430, binding = 18) writeonly buffer ScratchRho { real scratch_rho[]; };
layout(std430, binding = 40) writeonly buffer ScratchVh { real4 scratch_vh[]; };
layout(std430, binding = 35) readonly buffer PickTable { uvec4 pick_table[]; };
layout(std430, binding = 36) readonly buffer PickBounds { vec4 pick_bounds[]; };
layout(std430, binding = 37) buffer PickCount { uint pick_count[]; };
layout(std430, binding = 38) readonly buffer LayerStart { uint layer_start[]; };  // (unread: named by pick_table.glsl)
layout(std430, binding = 44) readonly buffer BandRows { uvec2 band_rows[]; };
#include "pick_table.glsl"
#include "band_rows.glsl"
#include "integrate_row.glsl"

void main() {
    // [1] one invocation per row an entry reads (band_rows.glsl: an indirect dispatch of as many), entry after entry
    uint i;
    uint e;
    if (!band_row_at(gl_GlobalInvocationID.x, i, e) || i >= P.n) return;
    // [2] the row as it is, or at D.level 1 as integrate will store it (a body's wall particle stays)
    real4 x = particle_x[i];
    real4 v = particle_v[i];
    real4 vh = particle_vh[i];
    if (D.level == 1u && !(BODIES && particle_id[i] >= P.fluid_count)) {
        real3 stepped_x;
        real3 stepped_v;
        real3 stepped_vh;
        // (at a fixed dt before choose_dt: time_state's dt is the last step's; with an adaptive dt after it)
        float dt = ADAPTIVE_DT ? time_state[0].x : P.dt;
        float dt_prev = VERLET ? (ADAPTIVE_DT ? time_state[0].y : time_state[0].x) : 0.0;
        integrated(i, dt, dt_prev, real4(0.0), stepped_x, stepped_v, stepped_vh);
        x = real4(stepped_x, 0.0);
        v = real4(stepped_v, 0.0);
        if (VERLET) vh = real4(stepped_vh, 0.0);
    }
    // [3] its layer along the slab axis, as the sort finds it (clamped into the grid), and its coordinate
    uint axis = DIM - 1u;
    uint layer = uint(clamp(cell_of(x.xyz)[axis], 0, int(P.grid_dim[axis]) - 1));
    real coordinate = x[axis];
    // [4] whether its entry's rank (pick_table.glsl) takes it, and the slot it takes there: its entry's zones follow
    //     those of the entries before it
    uint slot = 0u;
    for (uint f = 0u; f < e; f++) slot += 2u * zone_of(band_rows[1u + f].y);
    uint zone = zone_of(band_rows[1u + e].y);
    uvec4 entry = pick_table[1u + e];
    uint k;
    if (layer >= entry.z && layer < entry.w) {
        k = slot + atomicAdd(pick_count[2u * e], 1u);
    } else if (coordinate >= real(pick_bounds[e].x) && coordinate < real(pick_bounds[e].y)) {
        k = slot + zone + atomicAdd(pick_count[2u * e + 1u], 1u);
    } else {
        return;
    }
    if (slot + 2u * zone > P.n) return;
    // [5] the row packed into slot k
    scratch_x[k] = x;
    scratch_v[k] = v;
    scratch_id[k] = particle_id[i];
    scratch_rho[k] = particle_rho[i];
    if (VERLET) scratch_vh[k] = vh;
}
