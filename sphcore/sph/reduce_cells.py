"""Build HistoPyramid level D.level from the level below: each node is the sum of its 8
children (seed 2's reduction, over the cells in index order). One invocation per node.

Mirror of shaders/sph/reduce_cells.comp: same names, same statement order, same step labels.
"""
from functools import lru_cache

import numpy as np
from numba import njit

from sphcore.pyramid import level_offset, level_size
from sphcore.sph.grid_range import grid_end, grid_first
from sphcore.workgroups import launcher


@lru_cache(maxsize=None)
def reduce_cells(spec, real=np.float32):
    @njit
    def reduce_cells_main(k, params, cell_pyramid):
        P = params[0]
        D = params[0]  # (the dispatch's push constants: on numba, fields of the same record)
        # [1] one invocation per node of level D.level over the grid's range (grid_range.glsl; the others are
        #     empty, and so every node above them only), from the range's first node on
        node = (grid_first(P) >> (3 * D.level)) + k
        size = level_size(P.cell_total, D.level)
        if node >= size or node > ((grid_end(P) - 1) >> (3 * D.level)):
            return
        # [2] children: nodes 8 node .. 8 node + 7 of the level below (fewer at its end)
        below = level_offset(P.cell_total, D.level - 1)
        below_size = level_size(P.cell_total, D.level - 1)
        total = 0
        for k in range(8):
            child = 8 * node + k
            if child < below_size:
                total += cell_pyramid[below + child]
        # [3] store
        cell_pyramid[level_offset(P.cell_total, D.level) + node] = total

    return launcher(reduce_cells_main)
