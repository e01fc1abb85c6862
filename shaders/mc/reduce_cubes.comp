#version 460
// Build HistoPyramid level P.level from the level below: each node is the sum of its 8
// children (seed 2's reduction, over the cubes in index order). One invocation per node.
// Mirror: sphcore/mc/reduce_cubes.py (same names, same statement order, same step labels).
#extension GL_GOOGLE_include_directive : require
layout(local_size_x_id = 0) in;
#include "params.glsl"
#include "constants.glsl"
#include "../pyramid.glsl"

layout(std430, binding = 2) buffer CubePyramid { uint cube_pyramid[]; };

void main() {
    // [1] one invocation per node of level P.level
    uint node = gl_GlobalInvocationID.x;
    uint size = level_size(P.cube_total, P.level);
    if (node >= size) return;
    // [2] children: nodes 8 node .. 8 node + 7 of the level below (fewer at its end)
    uint below = level_offset(P.cube_total, P.level - 1u);
    uint below_size = level_size(P.cube_total, P.level - 1u);
    uint sum = 0u;
    for (uint k = 0u; k < 8u; ++k) {
        uint child = 8u * node + k;
        if (child < below_size) sum += cube_pyramid[below + child];
    }
    // [3] store
    cube_pyramid[level_offset(P.cube_total, P.level) + node] = sum;
}
