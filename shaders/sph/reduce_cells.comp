#version 460
// Build HistoPyramid level D.level from the level below: each node is the sum of its 8
// children (seed 2's reduction, over the cells in index order). One invocation per node.
// Mirror: sphcore/sph/reduce_cells.py (same names, same statement order, same step labels).
#extension GL_GOOGLE_include_directive : require
layout(local_size_x_id = 0) in;
#include "params.glsl"
#include "constants.glsl"
#include "cells.glsl"
#include "grid_range.glsl"
#include "../pyramid.glsl"

layout(std430, binding = 8) buffer CellPyramid { uint cell_pyramid[]; };

void main() {
    // [1] one invocation per node of level D.level over the grid's range (grid_range.glsl; the others are
    //     empty, and so every node above them only), from the range's first node on
    uint node = (grid_first() >> (3u * D.level)) + gl_GlobalInvocationID.x;
    uint size = level_size(P.cell_total, D.level);
    if (node >= size || node > ((grid_end() - 1u) >> (3u * D.level))) return;
    // [2] children: nodes 8 node .. 8 node + 7 of the level below (fewer at its end)
    uint below = level_offset(P.cell_total, D.level - 1u);
    uint below_size = level_size(P.cell_total, D.level - 1u);
    uint sum = 0u;
    for (uint k = 0u; k < 8u; ++k) {
        uint child = 8u * node + k;
        if (child < below_size) sum += cell_pyramid[below + child];
    }
    // [3] store
    cell_pyramid[level_offset(P.cell_total, D.level) + node] = sum;
}
