#version 460
// Read the vertex total from the top of the HistoPyramid and write the indirect dispatch
// arguments of emit_vertices, so that no count travels to the host (seed 2). One invocation.
// Mirror: sphcore/mc/write_arguments.py (same names, same statement order, same step labels).
#extension GL_GOOGLE_include_directive : require
layout(local_size_x_id = 0) in;
#include "params.glsl"
#include "constants.glsl"
#include "../pyramid.glsl"

layout(std430, binding = 2) readonly buffer CubePyramid { uint cube_pyramid[]; };
layout(std430, binding = 3) writeonly buffer Arguments { uint arguments[]; };

const uint MAX_GROUPS_X = 65535u;  // the least maxComputeWorkGroupCount[0] Vulkan allows

void main() {
    // [1] one invocation
    if (gl_GlobalInvocationID.x != 0u) return;
    // [2] vertices to emit: all of them, or as many as the output holds (the host sees the
    //     total in arguments[3], enlarges the output and runs again: nothing is cut silently)
    uint total = cube_pyramid[level_offset(P.cube_total, P.levels)];
    uint groups = (min(total, P.capacity) + gl_WorkGroupSize.x - 1u) / gl_WorkGroupSize.x;
    // [3] (x, y, z) work groups, x at most MAX_GROUPS_X; then the total
    arguments[0] = min(groups, MAX_GROUPS_X);
    arguments[1] = (groups + MAX_GROUPS_X - 1u) / MAX_GROUPS_X;
    arguments[2] = 1u;
    arguments[3] = total;
}
