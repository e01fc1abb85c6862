"""Zero the per-cell particle counts (HistoPyramid level 0), one invocation per cell.

Mirror of shaders/sph/clear_cells.comp: same names, same statement order, same step labels.
"""
from functools import lru_cache

import numpy as np
from numba import njit

from sphcore.sph.grid_range import grid_end, grid_first
from sphcore.workgroups import launcher


@lru_cache(maxsize=None)
def clear_cells(spec, real=np.float32):
    @njit
    def clear_cells_main(k, params, cell_pyramid):
        P = params[0]
        # [1] one invocation per cell of the grid's range (grid_range.glsl; the others stay empty)
        c = grid_first(P) + k
        if c >= grid_end(P):
            return
        # [2] no particle counted yet
        cell_pyramid[c] = 0

    return launcher(clear_cells_main)
