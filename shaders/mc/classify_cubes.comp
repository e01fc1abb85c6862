#version 460
// Classify each cube (case 0..255, kept for the traversal) and put its vertex count into the
// base of the HistoPyramid (seed 2). One invocation per cube.
// Mirror: sphcore/mc/classify_cubes.py (same names, same statement order, same step labels).
#extension GL_GOOGLE_include_directive : require
layout(local_size_x_id = 0) in;
#include "params.glsl"
#include "constants.glsl"
#include "tables.glsl"

layout(std430, binding = 0) readonly buffer Volume { float volume[]; };
layout(std430, binding = 1) writeonly buffer CubeCase { uint cube_case[]; };
layout(std430, binding = 2) writeonly buffer CubePyramid { uint cube_pyramid[]; };
layout(std430, binding = 4) writeonly buffer VertexPosition { vec4 vertex_position[]; };
layout(std430, binding = 5) writeonly buffer VertexNormal { vec4 vertex_normal[]; };
layout(std430, binding = 6) writeonly buffer VertexKey { uint vertex_key[]; };
layout(std430, binding = 11) readonly buffer CaseVertices { uint case_vertices[]; };
layout(std430, binding = 12) readonly buffer CaseEdges { uint case_edges[]; };

#include "cubes.glsl"

void main() {
    // [1] one invocation per cube
    uint c = gl_GlobalInvocationID.x;
    if (c >= P.cube_total) return;
    // [2] case from the 8 corners, and its vertex count
    uint code = classify(cube_origin(c));
    cube_case[c] = code;
    cube_pyramid[c] = case_vertices[code];
}
