// One neighbour walk for the pair loops (compute_forces; TrixiParticles' foreach_neighbor): every other
// particle and every wall or obstacle image within h of particle i, each handed to `pair`, which the including
// shader defines before this file:
//     void pair(uint i, uint j, uint image, real3 r, real r2, real3 inward)
// (j: the neighbour, `image`: the walls and obstacle faces it is mirrored across, r = x_i - x_k, r2 = |r|^2,
// `inward`: near_obstacles' normals, for pairs.glsl's direction where the two coincide). `pair` loads what it
// needs of j first, then takes rlen = sqrt(r2) and the direction (pairs.glsl: pair_direction), and adds the
// pair's terms (pressure.glsl, viscosity.glsl, ...) to the shader's sums, private globals set before the walk.
// (Loads first, as the pair loops did before the walk.)
// With neighbour lists (MAX_NEIGHBOURS > 0, Scene.spec_for) the walk reads i's list as compute_density wrote it
// this step (neighbour_list.glsl: the pairs of the scan below, in its order, so the same bits; reused lists,
// LIST_SKIN: the pairs of the list now within h). A particle with more neighbours than its list's slots, and
// every particle without lists, is scanned: the images of `mirrored`'s bits (cells.glsl: near_walls; obstacles.glsl:
// near_obstacles) and the 3^dim cells around each image of x_built (where i was at the list's build with reused
// lists, else xi), or all pairs without the grid.
// Needs particle_x, scratch_x, cell_pyramid, cell_start, obstacle_box and the lists' buffers declared by the shader,
// after cells.glsl, kernels.glsl, pairs.glsl, obstacles.glsl and neighbour_list.glsl.
// Mirror: sphcore/sph/walk.py (same names, same statements).

// Hands every other particle and image within h of i (at xi) to `pair`, in the list's or the scan's order.
void walk_neighbours(uint i, real3 xi) {
    // the wall and obstacle images, as in compute_density (cells.glsl: near_walls, obstacles.glsl: near_obstacles):
    // bit a of `mirrored` says that the wall on axis a, or an obstacle's face where nearer, is within h; `inward`
    // points from each axis's mirror plane into the fluid. Reused lists (LIST_SKIN): the walls and cells of where i
    // was at the list's build (scratch_x)
    real3 x_built = LIST_SKIN > 0u ? scratch_x[i].xyz : xi;
    real3 wall;
    uint mirrored = LIST_SKIN > 0u ? near_walls_within(x_built, list_reach(), wall) : near_walls(xi, wall);
    real3 inward;
    mirrored = near_obstacles(xi, mirrored, wall, inward);
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
        // the 3^dim cells around xm, as ranges of sorted particles (cells.glsl: range_cells)
        for (uint k = 0u; k < range_count(); ++k) {
            uint start = 0u;
            uint end = P.n;
            if (GRID) {
                int first;
                int last;
                if (!range_cells(base, k, first, last)) continue;
                start = cell_start[first];
                end = cell_start[last] + cell_pyramid[last];
            }
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
