#version 460
// Seed 2's baseline, the geometry-shader method, as a GPU's subgroups run it: one invocation per run of
// CUBE_RUN cubes along z (each face of samples read once; CUBE_RUN = 1 is one invocation per cube). For
// each cube of the runs, the subgroup's cubes with vertices take their output slots with one atomic on a
// counter (arguments[3], cleared by the host), then the subgroup writes each such cube's vertices
// together, one lane per vertex: with one lane per cube, a few lanes walked their vertices while the
// rest waited. The output order depends on scheduling; the welded mesh does not.
// Mirror: sphcore/mc/emit_cubes.py (same names, same statement order, same step labels; a subgroup
// operation ends a phase, as a barrier does: sphcore/workgroups.py).
#extension GL_GOOGLE_include_directive : require
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_arithmetic : require
#extension GL_KHR_shader_subgroup_ballot : require
#extension GL_KHR_shader_subgroup_shuffle : require
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
    // [1] one invocation per run: its first cube's corner 0 and that cube's lowest face; an invocation
    //     past the last run has no cubes, and every invocation reaches the subgroup operations
    uint r = gl_GlobalInvocationID.x;
    uint nz = P.dim.z - 1u;
    uint runs = (nz + CUBE_RUN - 1u) / CUBE_RUN;
    bool inside = r < (P.dim.x - 1u) * (P.dim.y - 1u) * runs;
    uvec3 s = cube_origin(r / runs * nz);
    s.z = r % runs * CUBE_RUN;
    uint low = inside ? cube_face(s) : 0u;
    for (uint j = 0u; j < CUBE_RUN; ++j) {
        // [2] cube j of the run: its case from its two faces, its vertex count
        uint c = 0u;
        uint code = 0u;
        uint count = 0u;
        if (inside && s.z < nz) {
            uint high = cube_face(s + uvec3(0u, 0u, 1u));
            c = cube_index(s);
            code = low | (high << 4);
            count = case_vertices[code];
            low = high;
        }
        s.z += 1u;
        // [3] the subgroup's cubes with vertices take their output slots with one atomic (the subgroup's
        //     first invocation's); past the capacity they are counted but not written (the host sees the
        //     total in arguments[3], enlarges the output and runs again)
        uint total = subgroupAdd(count);
        if (total == 0u) continue;
        uint offset = subgroupExclusiveAdd(count);
        uint first = 0u;
        if (subgroupElect()) first = atomicAdd(arguments[3], total);
        first = subgroupBroadcastFirst(first);
        // [4] each cube with vertices, in lane order: its vertices written by the subgroup, one lane each
        uvec4 pending = subgroupBallot(count > 0u);
        uint busy = subgroupBallotBitCount(pending);
        for (uint k = 0u; k < busy; ++k) {
            uint lane = subgroupBallotFindLSB(pending);
            pending[lane / 32u] &= ~(1u << (lane % 32u));
            uint lane_c = subgroupShuffle(c, lane);
            uint lane_code = subgroupShuffle(code, lane);
            uint lane_count = subgroupShuffle(count, lane);
            uint lane_first = first + subgroupShuffle(offset, lane);
            for (uint v = gl_SubgroupInvocationID; v < lane_count; v += gl_SubgroupSize) {
                if (lane_first + v < P.capacity) emit_vertex(lane_c, lane_code, v, lane_first + v);
            }
        }
    }
}
