#version 460
// Start of each cell's run in the sorted order: the number of particles in all cells before
// it, read from the HistoPyramid top-down (seed 2), and of each cell layer's (the grid's slowest
// index: a rank of sphcore.parallel reads them after a step). One invocation per cell.
// Mirror: sphcore/sph/cell_offsets.py (same names, same statement order, same step labels).
#extension GL_GOOGLE_include_directive : require
layout(local_size_x_id = 0) in;
#include "params.glsl"
#include "constants.glsl"
#include "cells.glsl"
#include "grid_range.glsl"
#include "../pyramid.glsl"

layout(std430, binding = 8) readonly buffer CellPyramid { uint cell_pyramid[]; };
layout(std430, binding = 9) writeonly buffer CellStart { uint cell_start[]; };
layout(std430, binding = 14) buffer GridStatus { uint grid_status[]; };
layout(std430, binding = 38) writeonly buffer LayerStart { uint layer_start[]; };

void main() {
    // [1] one invocation per cell of the grid's range (grid_range.glsl); outside it no cell holds a
    //     particle: a layer's first row is 0 before the range, n after it (the range's first cell writes those)
    uint c = grid_first() + gl_GlobalInvocationID.x;
    uint layers = DIM == 3u ? P.grid_dim.z : P.grid_dim.y;
    uint per_layer = P.cell_total / layers;
    if (c == grid_first()) {
        for (uint layer = 0u; layer < grid_first() / per_layer; ++layer) layer_start[layer] = 0u;
        for (uint layer = grid_end() / per_layer; layer < layers; ++layer) layer_start[layer] = P.n;
    }
    if (c >= grid_end()) return;
    // [2] from the top level down: at level l the cell's ancestor is c / 8^l, and every
    //     sibling before that ancestor (same parent) counts particles that come before c
    uint start = 0u;
    for (int l = int(P.levels) - 1; l >= 0; --l) {
        uint ancestor = c >> (3u * uint(l));
        uint offset = level_offset(P.cell_total, uint(l));
        for (uint s = ancestor & ~7u; s < ancestor; ++s) {
            start += cell_pyramid[offset + s];
        }
    }
    cell_start[c] = start;
    // [3] a layer's first cell: the layer's start
    if (c % per_layer == 0u) layer_start[c / per_layer] = start;
    // [4] the top of the pyramid must hold every particle exactly once; a mismatch is counted
    //     in grid_status[2] (an overflow or a lost particle: never silently accepted)
    if (c == grid_first() && cell_pyramid[level_offset(P.cell_total, P.levels)] != P.n) atomicAdd(grid_status[2], 1u);
}
