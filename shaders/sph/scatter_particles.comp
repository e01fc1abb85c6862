#version 460
// Put each particle's index at its cell's start plus its slot: a counting sort by cell.
// One invocation per particle.
// Mirror: sphcore/sph/scatter_particles.py (same names, same statement order, same step labels).
#extension GL_GOOGLE_include_directive : require
layout(local_size_x_id = 0) in;
#include "params.glsl"
#include "constants.glsl"

layout(std430, binding = 6) readonly buffer ParticleCell { uint particle_cell[]; };
layout(std430, binding = 7) readonly buffer ParticleSlot { uint particle_slot[]; };
layout(std430, binding = 9) readonly buffer CellStart { uint cell_start[]; };
layout(std430, binding = 10) writeonly buffer SortedIndex { uint sorted_index[]; };

void main() {
    // [1] one invocation per particle
    uint i = gl_GlobalInvocationID.x;
    if (i >= P.n) return;
    // [2] slots of one cell are distinct and below its count, so every position is written once
    sorted_index[cell_start[particle_cell[i]] + particle_slot[i]] = i;
}
