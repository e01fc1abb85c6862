"""Order each cell's particles by their current index (insertion sort of the cell's run), so
the sorted order is (cell, index) whatever order the atomic slots were taken in: Vulkan and
numba produce the same permutation bit for bit. With ID_ORDER by their id: (cell, id), the
order whatever rows the particles are held in (sphcore.parallel: a rank's set changes every step). One invocation per cell.

Mirror of shaders/sph/sort_cells.comp: same names, same statement order, same step labels.
"""
from functools import lru_cache

import numpy as np
from numba import njit

from sphcore.sph.grid_range import grid_end, grid_first
from sphcore.workgroups import launcher


@lru_cache(maxsize=None)
def sort_cells(spec, real=np.float32):
    ID_ORDER = spec.ID_ORDER

    @njit
    def sort_key(i, particle_id):
        return particle_id[i] if ID_ORDER else np.uint32(i)

    @njit
    def sort_cells_main(k, params, cell_pyramid, cell_start, sorted_index, particle_id):
        P = params[0]
        # [1] one invocation per cell of the grid's range (grid_range.glsl; the others are empty)
        c = grid_first(P) + k
        if c >= grid_end(P):
            return
        # [2] the cell's run in the sorted order
        start = cell_start[c]
        count = cell_pyramid[c]
        # [3] insertion sort, ascending particle index (ID_ORDER: id)
        for k in range(1, count):
            key = sorted_index[start + k]
            m = k
            while m > 0 and sort_key(sorted_index[start + m - 1], particle_id) > sort_key(key, particle_id):
                sorted_index[start + m] = sorted_index[start + m - 1]
                m -= 1
            sorted_index[start + m] = key

    return launcher(sort_cells_main)
