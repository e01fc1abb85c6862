#version 460
// On a rank of sphcore.parallel, after the step's sort: the rows its pick reads (pick_table.glsl: each entry's, the
// rows the sort gave its layers) into band_rows (band_rows.glsl), and their count in work groups into rank_groups[0]
// (x, 1, 1, the rows), which the indirect dispatches of compute_forces' first pass, pick_rows and pack_rows read: one
// invocation a row (pack_rows sends fewer), where a dispatch over every row held cost an H200 0.07-0.4 ms a stage at
// 17 M rows. One invocation.
// Mirror: sphcore/sph/pick_groups.py (same names, same statement order, same step labels).
#extension GL_GOOGLE_include_directive : require
layout(local_size_x_id = 0) in;
#include "params.glsl"
#include "constants.glsl"

layout(std430, binding = 35) readonly buffer PickTable { uvec4 pick_table[]; };
layout(std430, binding = 38) readonly buffer LayerStart { uint layer_start[]; };
layout(std430, binding = 44) writeonly buffer BandRows { uvec2 band_rows[]; };
layout(std430, binding = 45) writeonly buffer RankGroups { uvec4 rank_groups[]; };
#include "pick_table.glsl"

void main() {
    // [1] one invocation
    if (gl_GlobalInvocationID.x != 0u) return;
    // [2] each entry's rows, and their count
    uint entries = pick_table[0].x;
    uint rows = 0u;
    band_rows[0] = uvec2(entries, 0u);
    for (uint e = 0u; e < entries; e++) {
        uvec2 entry = entry_rows(e);
        band_rows[1u + e] = entry;
        rows += entry.y;
    }
    // [3] the dispatch of one invocation a row
    rank_groups[0] = uvec4((rows + gl_WorkGroupSize.x - 1u) / gl_WorkGroupSize.x, 1u, 1u, rows);
}
