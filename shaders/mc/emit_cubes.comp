#version 460
// Seed 2's baseline, the geometry-shader method: one invocation per cube classifies it and
// writes its own vertices at slots taken from an atomic counter (arguments[3], cleared by the
// host). The output order depends on scheduling; the welded mesh does not.
// Mirror: sphcore/mc/emit_cubes.py (same names, same statement order, same step labels).
#extension GL_GOOGLE_include_directive : require
layout(local_size_x_id = 0) in;
#include "params.glsl"
#include "constants.glsl"
#include "tables.glsl"

layout(std430, binding = 0) readonly buffer Volume { float volume[]; };
layout(std430, binding = 3) buffer Arguments { uint arguments[]; };
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
    // [2] case and vertex count
    uint code = classify(cube_origin(c));
    uint count = case_vertices[code];
    if (count == 0u) return;
    // [3] take `count` output slots; past the capacity they are counted but not written (the
    //     host sees the total in arguments[3], enlarges the output and runs again)
    uint first = atomicAdd(arguments[3], count);
    if (first + count > P.capacity) return;
    // [4] write the vertices
    for (uint k = 0u; k < count; ++k) {
        emit_vertex(c, code, k, first + k);
    }
}
