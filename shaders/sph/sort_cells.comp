#version 460
// Order each cell's particles by their current index (insertion sort of the cell's run), so
// the sorted order is (cell, index) whatever order the atomic slots were taken in: Vulkan and
// numba produce the same permutation bit for bit. With ID_ORDER by their id: (cell, id), the
// order whatever rows the particles are held in (sphcore.parallel: a rank's set changes every step).
// One invocation per cell; a cell holds about (h / spacing)^dim particles, so the sort is short
// (quadratic only if all crowd one cell).
// Mirror: sphcore/sph/sort_cells.py (same names, same statement order, same step labels).
#extension GL_GOOGLE_include_directive : require
layout(local_size_x_id = 0) in;
#include "params.glsl"
#include "constants.glsl"
#include "grid_range.glsl"

layout(std430, binding = 8) readonly buffer CellPyramid { uint cell_pyramid[]; };
layout(std430, binding = 9) readonly buffer CellStart { uint cell_start[]; };
layout(std430, binding = 10) buffer SortedIndex { uint sorted_index[]; };
layout(std430, binding = 5) readonly buffer ParticleId { uint particle_id[]; };  // ID_ORDER: the key

uint sort_key(uint i) { return ID_ORDER ? particle_id[i] : i; }

void main() {
    // [1] one invocation per cell of the grid's range (grid_range.glsl; the others are empty)
    uint c = grid_first() + gl_GlobalInvocationID.x;
    if (c >= grid_end()) return;
    // [2] the cell's run in the sorted order
    uint start = cell_start[c];
    uint count = cell_pyramid[c];
    // [3] insertion sort, ascending particle index (ID_ORDER: id)
    for (uint k = 1u; k < count; ++k) {
        uint key = sorted_index[start + k];
        uint m = k;
        while (m > 0u && sort_key(sorted_index[start + m - 1u]) > sort_key(key)) {
            sorted_index[start + m] = sorted_index[start + m - 1u];
            m -= 1u;
        }
        sorted_index[start + m] = key;
    }
}
