"""Neighbour-grid helpers shared by the grid and SPH mirrors.

Mirror of shaders/sph/cells.glsl: same names, same statements. GLSL reads the parameter
block as a global `P`; here it is the first argument. A GLSL ivec3 is three ints.
"""
from functools import lru_cache

import numpy as np
from numba import njit

f32 = np.float32
CELL_LIMIT = 1 << 24  # |cell coordinate| beyond this: outside the hashed range


@lru_cache(maxsize=None)
def cells(spec):
    DIM, WALLS = spec.DIM, spec.WALLS

    @njit
    def cell_of(P, x_x, x_y, x_z):
        """Cell coordinates of point x, clamped to +-CELL_LIMIT (z = 0 in 2D)."""
        f_x = np.floor((x_x - P.box_min[0]) * P.inv_cell)
        f_y = np.floor((x_y - P.box_min[1]) * P.inv_cell)
        f_z = np.floor((x_z - P.box_min[2]) * P.inv_cell)
        f_x = min(max(f_x, f32(-CELL_LIMIT)), f32(CELL_LIMIT))
        f_y = min(max(f_y, f32(-CELL_LIMIT)), f32(CELL_LIMIT))
        f_z = min(max(f_z, f32(-CELL_LIMIT)), f32(CELL_LIMIT))
        if DIM == 2:
            f_z = f32(0.0)
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

    return cell_of, cell_index


@njit
def level_offset(P, l):
    """Offset of HistoPyramid level l in the pyramid buffer."""
    offset = 0
    size = int(P.cell_total)
    for k in range(l):
        offset += size
        size = (size + 7) // 8
    return offset


@njit
def level_size(P, l):
    """Node count of HistoPyramid level l."""
    size = int(P.cell_total)
    for k in range(l):
        size = (size + 7) // 8
    return size
