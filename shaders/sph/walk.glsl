// The neighbour walk (TrixiParticles' foreach_neighbor), two entry points:
//   walk_neighbours(i, xi): every other particle and every wall or obstacle image within h of particle i, each
//     handed to `pair` (compute_forces, wall_pressure). With neighbour lists (MAX_NEIGHBOURS > 0, Scene.spec_for)
//     it reads i's list as compute_density wrote it this step (neighbour_list.glsl: the pairs of compute_density's
//     scan, in its order, so the same bits; reused lists, LIST_SKIN: the pairs of the list now within h). A
//     particle with more neighbours than its list's slots, and every particle without lists, is scanned: the images
//     of `mirrored`'s bits (cells.glsl: near_walls; obstacles.glsl: near_obstacles) and the 3^dim cells around each
//     image of x_built (where i was at the list's build with reused lists, else xi; cell_ranges.glsl), or all pairs
//     without the grid.
//   walk_list(i, count): i's list slot by slot, each slot to `list_entry` (the DFSPH sweeps dfsph_factor,
//     dfsph_residual and dfsph_velocity). Apart from walk_neighbours' list loop because these need the slot, which
//     `pair` does not get: dfsph_factor stores each entry's gradient at it, and with GRADIENTS the solves read it
//     there without loading the neighbour's position (neighbour_list.glsl: listed_gradient).
// compute_density scans with its own loop, the walk's scan written out: it keeps i itself, writes the lists (list
// first, by chunks, out to list_reach at a reused list's build) and sums in the scan's order. The same scan through
// walk.glsl's hooks, its sums and list in private globals, cost that stage 6 % on an H200 (0.409 to 0.434 ms a step
// at 1 M particles, benchmarks/gpu_step_ab.sh; writing its chunk by selects instead: 0.460), so it stays written out,
// its cell ranges too (through cell_ranges.glsl the whole step ran 0.8 % slower). It shares mirror_planes.
// The including shader defines the hook it calls before this file:
//     void pair(uint i, uint j, uint image, real3 r, real r2, real3 inward)
//     void list_entry(uint i, uint slot, inout uvec4 chunk)
// (j: the neighbour, `image`: the walls and obstacle faces it is mirrored across, r = x_i - x_k, r2 = |r|^2,
// `inward`: near_obstacles' normals, for pairs.glsl's direction where the two coincide). Both are declared here, so
// a shader that calls one entry point need not define the other's hook (a function no code reaches needs no body).
// `pair` loads what it needs of j first, then takes rlen = sqrt(r2) and the direction (pairs.glsl:
// pair_direction), and adds the pair's terms (pressure.glsl, viscosity.glsl, ...) to the shader's sums, private
// globals set before the walk.
// Needs particle_x, scratch_x, cell_pyramid, cell_start, obstacle_box and the lists' buffers declared by the shader,
// after cells.glsl, kernels.glsl, pairs.glsl, obstacles.glsl and neighbour_list.glsl.
// Mirror: sphcore/sph/walk.py (same names, same statements).
#include "cell_ranges.glsl"

void pair(uint i, uint j, uint image, real3 r, real r2, real3 inward);
void list_entry(uint i, uint slot, inout uvec4 chunk);

// Hands every other particle and image within h of i (at xi) to `pair`, in the list's or the scan's order.
void walk_neighbours(uint i, real3 xi) {
    // the wall and obstacle images, as in compute_density (obstacles.glsl: mirror_planes):
    // bit a of `mirrored` says that the wall on axis a, or an obstacle's face where nearer, is within h; `inward`
    // points from each axis's mirror plane into the fluid. Reused lists (LIST_SKIN): the walls and cells of where i
    // was at the list's build (scratch_x)
    real3 x_built = LIST_SKIN > 0u ? scratch_x[i].xyz : xi;
    real3 wall;
    real3 inward;
    uint mirrored = mirror_planes(x_built, xi, wall, inward);
    // i's list where it fits its slots, else the scan (below: the list's loop after the scan's, an order in
    // which the GPU's compiler keeps the two loops apart: with reused lists, where both end alike, the other
    // order cost compute_forces 8 % on an H200, issue 31)
    bool listed = MAX_NEIGHBOURS > 0u && neighbour_count[i] <= MAX_NEIGHBOURS;
    // the scan: image `image` mirrors the axes of its bits; the image of j is within h of xi exactly when
    // j is within h of xi's own image xm, so the cells searched are those around xm
    for (uint image = 0u; image < 8u; ++image) {
        if (listed || (image & ~mirrored) != 0u) continue;
        real3 xm = reflected(x_built, wall, image);
        ivec3 base = cell_of(xm);
        // the 3^dim cells around xm, as ranges of sorted particles (cell_ranges.glsl)
        for (uint k = 0u; k < range_count(); ++k) {
            uint start;
            uint end;
            if (!cell_range(base, k, start, end)) continue;
            for (uint j = start; j < end; ++j) {
                if (j == i && image == 0u) continue;
                real3 xk = particle_x[j].xyz;
                if (image != 0u) xk = reflected(xk, wall, image);
                if (OBSTACLES > 0u && image != 0u && !solid(xk)) continue;  // (obstacles.glsl)
                real3 r = xi - xk;
                real r2 = r.x * r.x + r.y * r.y + r.z * r.z;
                if (r2 >= P.h2) continue;
                pair(i, j, image, r, r2, inward);
            }
        }
    }
    // the list
    if (listed) {
        uint count = neighbour_count[i];
        uvec4 chunk = uvec4(0u);
        for (uint slot = 0u; slot < count; ++slot) {
            uint j;
            uint image;
            real3 r;
            real r2 = listed_distance(i, slot, chunk, xi, wall, j, image, r);
            if (LIST_SKIN > 0u && r2 >= P.h2) continue;  // (a reused list holds pairs out to list_reach)
            pair(i, j, image, r, r2, inward);
        }
    }
}

// Hands the first `count` slots of i's list (as compute_density wrote it this step) to `list_entry`, in the list's
// order, with the chunk they are read through (neighbour_list.glsl: listed_word).
void walk_list(uint i, uint count) {
    uvec4 chunk = uvec4(0u);
    for (uint slot = 0u; slot < count; ++slot) list_entry(i, slot, chunk);
}
