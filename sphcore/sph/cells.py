"""Neighbour-grid helpers shared by the grid and SPH mirrors.

Mirror of shaders/sph/cells.glsl: same names, same statements. GLSL reads the parameter
block as a global `P`; here it is the first argument. A GLSL ivec3 is three ints; `real`
is the shader's `real` (shaders/sph/real.glsl; default float32 for shaders/mc/sample_field).
"""
from functools import lru_cache

import numpy as np
from numba import njit
from sphcore.sph import named

CELL_LIMIT = 1 << 24  # |cell coordinate| beyond this: outside the hashed range


@lru_cache(maxsize=None)
def skin(spec, real=np.float32):
    """near_walls_within, list_reach, moved_limit2 (cells.glsl; the lists' skin, LIST_SKIN)."""
    DIM, WALLS, LIST_SKIN = spec.DIM, spec.WALLS, spec.LIST_SKIN

    @njit
    def near_walls_within(P, x_x, x_y, x_z, reach):
        """Wall images: (mirrored, wall): bit a of mirrored is set where the wall nearer to x on
        axis a is within `reach`, so that x also sees every particle mirrored across it."""
        wall_x = P.box_min[0] if x_x - P.box_min[0] < reach else P.box_max[0]
        wall_y = P.box_min[1] if x_y - P.box_min[1] < reach else P.box_max[1]
        wall_z = P.box_min[2] if x_z - P.box_min[2] < reach else P.box_max[2]
        mirrored = 0
        if WALLS and abs(x_x - wall_x) < reach:
            mirrored |= 1
        if WALLS and abs(x_y - wall_y) < reach:
            mirrored |= 2
        if WALLS and DIM == 3 and abs(x_z - wall_z) < reach:
            mirrored |= 4
        return mirrored, wall_x, wall_y, wall_z

    # Lists reused between builds (LIST_SKIN > 0, physics.list_skin = s): a build lists every particle and image
    # within list_reach() = (1 + s) h, and the lists serve until a particle has moved more than moved_limit2()'s
    # root, s h / 2.05, from where it was at the build (cells.glsl says why that suffices).
    @njit
    def list_reach(P):
        return real(P.h) * (real(1000 + LIST_SKIN) / real(1000.0))

    @njit
    def moved_limit2(P):
        return real(P.h2) * (real(LIST_SKIN * LIST_SKIN) / real(4202500.0))

    return named(near_walls_within, list_reach, moved_limit2)


@lru_cache(maxsize=None)
def cells(spec, real=np.float32):
    DIM, GRID, WALLS, CELL_SPLIT = spec.DIM, spec.GRID, spec.WALLS, spec.CELL_SPLIT

    @njit
    def cell_of(P, x_x, x_y, x_z):
        """Cell coordinates of point x, clamped to +-CELL_LIMIT (z = 0 in 2D)."""
        f_x = np.floor((x_x - P.box_min[0]) * P.inv_cell)
        f_y = np.floor((x_y - P.box_min[1]) * P.inv_cell)
        f_z = np.floor((x_z - P.box_min[2]) * P.inv_cell)
        f_x = min(max(f_x, real(-CELL_LIMIT)), real(CELL_LIMIT))
        f_y = min(max(f_y, real(-CELL_LIMIT)), real(CELL_LIMIT))
        f_z = min(max(f_z, real(-CELL_LIMIT)), real(CELL_LIMIT))
        if DIM == 2:
            f_z = real(0.0)
        return int(f_x), int(f_y), int(f_z)

    @njit
    def cell_index(P, c_x, c_y, c_z):
        """Index of cell c: -1 outside the box (walls), else wrapped into the period (open)."""
        d_x, d_y, d_z = int(P.grid_dim[0]), int(P.grid_dim[1]), int(P.grid_dim[2])
        if WALLS:
            if c_x < 0 or c_y < 0 or c_z < 0 or c_x >= d_x or c_y >= d_y or c_z >= d_z:
                return -1
        else:
            # c + d * (CELL_LIMIT / d + 2) >= 0, so % acts on non-negative numbers only
            c_x = (c_x + d_x * (CELL_LIMIT // d_x + 2)) % d_x
            c_y = (c_y + d_y * (CELL_LIMIT // d_y + 2)) % d_y
            c_z = (c_z + d_z * (CELL_LIMIT // d_z + 2)) % d_z
        return (c_z * d_y + c_y) * d_x + c_x

    near_walls_within = skin(spec, real).near_walls_within

    @njit
    def near_walls(P, x_x, x_y, x_z):
        """The walls within h."""
        return near_walls_within(P, x_x, x_y, x_z, real(P.h))

    @njit
    def reflected(x_x, x_y, x_z, wall_x, wall_y, wall_z, image):
        """Point x mirrored across the walls of the axes whose bits are set in `image`."""
        return (real(2.0) * wall_x - x_x if (image & 1) != 0 else x_x,
                real(2.0) * wall_y - x_y if (image & 2) != 0 else x_y,
                real(2.0) * wall_z - x_z if (image & 4) != 0 else x_z)

    @njit
    def range_count():
        """Ranges of sorted particles that hold the w^dim cells around a cell, w = 2 CELL_SPLIT + 1 (see
        cells.glsl)."""
        w = 2 * CELL_SPLIT + 1
        return ((w * w if DIM == 3 else w) if WALLS else (w * w * w if DIM == 3 else w * w)) if GRID else 1

    @njit
    def range_cells(P, base_x, base_y, base_z, k):
        """(inside, first, last): first and last cell of range k around cell `base`."""
        w = 2 * CELL_SPLIT + 1
        s = CELL_SPLIT
        row = k if WALLS else k // w
        c_x = base_x + (-s if WALLS else k % w - s)
        c_y = base_y + row % w - s
        c_z = base_z + row // w - (s if DIM == 3 else 0)
        c_last_x = c_x
        if WALLS:
            c_x = max(c_x, 0)
            c_last_x = min(c_last_x + 2 * s, int(P.grid_dim[0]) - 1)
            if c_x > c_last_x:
                return False, -1, -1
        first = cell_index(P, c_x, c_y, c_z)
        last = cell_index(P, c_last_x, c_y, c_z)
        return first >= 0, first, last

    return named(cell_of, cell_index, near_walls, reflected, range_count, range_cells)
