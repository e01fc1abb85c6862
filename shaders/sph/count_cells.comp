#version 460
// Each particle finds its cell and takes a slot in it by an atomic count, one invocation per
// particle. The slot order depends on scheduling; sort_cells makes it deterministic.
// Mirror: sphcore/sph/count_cells.py (same names, same statement order, same step labels).
#extension GL_GOOGLE_include_directive : require
layout(local_size_x_id = 0) in;
#include "params.glsl"
#include "constants.glsl"
#include "real.glsl"
#include "cells.glsl"

layout(std430, binding = 0) readonly buffer ParticleX { real4 particle_x[]; };
layout(std430, binding = 5) readonly buffer ParticleId { uint particle_id[]; };
layout(std430, binding = 6) writeonly buffer ParticleCell { uint particle_cell[]; };
layout(std430, binding = 7) writeonly buffer ParticleSlot { uint particle_slot[]; };
layout(std430, binding = 8) buffer CellPyramid { uint cell_pyramid[]; };
layout(std430, binding = 14) buffer GridStatus { uint grid_status[]; };

void main() {
    // [1] one invocation per particle
    uint i = gl_GlobalInvocationID.x;
    if (i >= P.n) return;
    // [2] cell coordinates; a particle outside the grid's range (past a wall, beyond the hashed
    //     range, or not finite) is counted in grid_status[0] and the lowest such id kept in
    //     grid_status[1]; it still gets a cell (0), so no particle is ever dropped
    real3 x = particle_x[i].xyz;
    ivec3 c = cell_of(x);
    real3 f = floor((x - P.box_min) * P.inv_cell);
    bool inside = WALLS ? all(greaterThanEqual(f, real3(0.0))) && all(lessThanEqual(f, real3(P.grid_dim)))
                        : all(lessThan(abs(f), real3(real(CELL_LIMIT))));
    if (!inside) {
        atomicAdd(grid_status[0], 1u);
        atomicMin(grid_status[1], particle_id[i]);
        c = ivec3(0);
    }
    // [3] a particle exactly on the upper wall belongs to the last cell
    if (WALLS) c = min(c, ivec3(P.grid_dim) - 1);
    uint cell = uint(cell_index(c));
    // [4] count, and take the next free slot of the cell
    particle_cell[i] = cell;
    particle_slot[i] = atomicAdd(cell_pyramid[cell], 1u);
}
