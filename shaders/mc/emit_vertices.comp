#version 460
// One invocation per output vertex (dispatched indirectly, write_arguments): walk the
// HistoPyramid from its top down to the cube that holds vertex v, then place the vertex on
// the cube's edge (seed 2). Vertices come out in cube order, 3 per triangle.
// Mirror: sphcore/mc/emit_vertices.py (same names, same statement order, same step labels).
#extension GL_GOOGLE_include_directive : require
layout(local_size_x_id = 0) in;
#include "params.glsl"
#include "constants.glsl"
#include "tables.glsl"
#include "../pyramid.glsl"

layout(std430, binding = 0) readonly buffer Volume { float volume[]; };
layout(std430, binding = 1) readonly buffer CubeCase { uint cube_case[]; };
layout(std430, binding = 2) readonly buffer CubePyramid { uint cube_pyramid[]; };
layout(std430, binding = 3) readonly buffer Arguments { uint arguments[]; };
layout(std430, binding = 4) writeonly buffer VertexPosition { vec4 vertex_position[]; };
layout(std430, binding = 5) writeonly buffer VertexNormal { vec4 vertex_normal[]; };
layout(std430, binding = 6) writeonly buffer VertexKey { uint vertex_key[]; };
layout(std430, binding = 12) readonly buffer CaseEdges { uint case_edges[]; };

#include "cubes.glsl"

void main() {
    // [1] one invocation per output vertex (the dispatch may be two-dimensional)
    uint v = (gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x) * gl_WorkGroupSize.x
             + gl_LocalInvocationID.x;
    if (v >= min(arguments[3], P.capacity)) return;
    // [2] from the top down: at each level step over the children whose vertices all come
    //     before v (start counts them), and descend into the child that holds v
    uint node = 0u;
    uint start = 0u;
    for (int l = int(P.levels) - 1; l >= 0; --l) {
        uint offset = level_offset(P.cube_total, uint(l));
        uint child = 8u * node;
        uint count = cube_pyramid[offset + child];
        for (uint k = 0u; k < 7u && v >= start + count; ++k) {
            start += count;
            child += 1u;
            count = cube_pyramid[offset + child];
        }
        node = child;
    }
    // [3] node is now the cube; v is its vertex v - start
    emit_vertex(node, cube_case[node], v - start, v);
}
