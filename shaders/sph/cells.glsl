// Neighbour-grid helpers shared by the grid and SPH shaders.
// Mirror: sphcore/sph/cells.py (same names, same statements).
//
// Cells are cubes of side 1 / P.inv_cell (h / CELL_SPLIT, padded by 2^-12 so that rounding in the cell
// coordinate can never put two particles closer than h more than CELL_SPLIT cells apart), counted from
// P.box_min. With walls the grid covers the box; in an open domain cell coordinates wrap modulo
// P.grid_dim (spatial hashing, seed 2): far-apart cells share a bucket, which is harmless because
// every pair's distance is tested against h. The HistoPyramid over the per-cell counts has the
// cells as its base (shaders/pyramid.glsl). Positions are `real` (real.glsl).

#include "real.glsl"

const int CELL_LIMIT = 1 << 24;  // |cell coordinate| beyond this: outside the hashed range

// Cell coordinates of point x, clamped to +-CELL_LIMIT (z = 0 in 2D).
ivec3 cell_of(real3 x) {
    real3 f = floor((x - P.box_min) * P.inv_cell);
    f = clamp(f, real3(-real(CELL_LIMIT)), real3(real(CELL_LIMIT)));
    if (DIM == 2u) f.z = real(0.0);
    return ivec3(f);
}

// Index of cell c in the grid: -1 outside the box (walls), else wrapped into the period (open).
int cell_index(ivec3 c) {
    ivec3 d = ivec3(P.grid_dim);
    if (WALLS) {
        if (c.x < 0 || c.y < 0 || c.z < 0 || c.x >= d.x || c.y >= d.y || c.z >= d.z) return -1;
    } else {
        // c + d * (CELL_LIMIT / d + 2) >= 0, so % acts on non-negative numbers only
        c = (c + d * (CELL_LIMIT / d + 2)) % d;
    }
    return (c.z * d.y + c.y) * d.x + c.x;
}

// Wall images: bit a of the result is set where the wall nearer to x on axis a (returned in
// `wall`) is within `reach`, so that x also sees every particle mirrored across it (walls only; z in 3D).
uint near_walls_within(real3 x, real reach, out real3 wall) {
    wall = real3(x.x - P.box_min.x < reach ? P.box_min.x : P.box_max.x,
                 x.y - P.box_min.y < reach ? P.box_min.y : P.box_max.y,
                 x.z - P.box_min.z < reach ? P.box_min.z : P.box_max.z);
    uint mirrored = 0u;
    if (WALLS && abs(x.x - wall.x) < reach) mirrored |= 1u;
    if (WALLS && abs(x.y - wall.y) < reach) mirrored |= 2u;
    if (WALLS && DIM == 3u && abs(x.z - wall.z) < reach) mirrored |= 4u;
    return mirrored;
}

// The walls within h.
uint near_walls(real3 x, out real3 wall) { return near_walls_within(x, real(P.h), wall); }

// Lists reused between builds (LIST_SKIN > 0, physics.list_skin = s): a build lists every particle and image
// within list_reach() = (1 + s) h (the cells are that size then: Scene.grid_dim), and the lists serve until a
// particle has moved more than moved_limit2()'s root, s h / 2.05, from where it was at the build (integrate.comp
// asks for the next build): a pair within h now was within h + s h / 1.025 at the build, so in the list. A
// particle's walls and the cells of a scan are those of where it was at the build (scratch_x), so that the
// images and cells of its list do not change while the list serves.
real list_reach() { return real(P.h) * (real(1000u + LIST_SKIN) / real(1000.0)); }
real moved_limit2() { return real(P.h2) * (real(LIST_SKIN * LIST_SKIN) / real(4202500.0)); }

// Point x mirrored across the walls of the axes whose bits are set in `image`.
real3 reflected(real3 x, real3 wall, uint image) {
    return real3((image & 1u) != 0u ? 2.0 * wall.x - x.x : x.x, (image & 2u) != 0u ? 2.0 * wall.y - x.y : x.y,
                 (image & 4u) != 0u ? 2.0 * wall.z - x.z : x.z);
}

// Ranges of sorted particles that hold the w^dim cells around a cell, w = 2 CELL_SPLIT + 1: with walls
// the w cells of an x-row are consecutive in the sorted order, so a row is one range (clipped to the
// box); in an open domain the hash may wrap a row, so each cell is a range of its own. Without
// the grid, one range holds every particle.
uint range_count() {
    uint w = 2u * CELL_SPLIT + 1u;
    return GRID ? (WALLS ? (DIM == 3u ? w * w : w) : (DIM == 3u ? w * w * w : w * w)) : 1u;
}

// First and last cell of range k around cell `base`; false where the range is outside the box.
bool range_cells(ivec3 base, uint k, out int first, out int last) {
    uint w = 2u * CELL_SPLIT + 1u;
    int s = int(CELL_SPLIT);
    uint row = WALLS ? k : k / w;
    ivec3 c = base + ivec3(WALLS ? -s : int(k % w) - s, int(row % w) - s, int(row / w) - (DIM == 3u ? s : 0));
    ivec3 c_last = c;
    if (WALLS) {
        c.x = max(c.x, 0);
        c_last.x = min(c_last.x + 2 * s, int(P.grid_dim.x) - 1);
        if (c.x > c_last.x) return false;
    }
    first = cell_index(c);
    last = cell_index(c_last);
    return first >= 0;
}
