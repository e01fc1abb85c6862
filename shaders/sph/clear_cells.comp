#version 460
// Zero the per-cell particle counts (HistoPyramid level 0), one invocation per cell.
// Mirror: sphcore/sph/clear_cells.py (same names, same statement order, same step labels).
#extension GL_GOOGLE_include_directive : require
layout(local_size_x_id = 0) in;
#include "params.glsl"
#include "constants.glsl"
#include "grid_range.glsl"

layout(std430, binding = 8) writeonly buffer CellPyramid { uint cell_pyramid[]; };

void main() {
    // [1] one invocation per cell of the grid's range (grid_range.glsl; the others stay empty)
    uint c = grid_first() + gl_GlobalInvocationID.x;
    if (c >= grid_end()) return;
    // [2] no particle counted yet
    cell_pyramid[c] = 0u;
}
