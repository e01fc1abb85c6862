"""Start of each cell's run in the sorted order: the number of particles in all cells before
it, read from the HistoPyramid top-down (seed 2), and of each cell layer's (the grid's slowest
index: a rank of sphcore.parallel reads them after a step). One invocation per cell.

Mirror of shaders/sph/cell_offsets.comp: same names, same statement order, same step labels.
The atomic on grid_status is made by the range's first invocation alone, so a parallel launch is exact.
"""
from functools import lru_cache

import numpy as np
from numba import njit

from sphcore.pyramid import level_offset
from sphcore.sph.grid_range import grid_end, grid_first
from sphcore.workgroups import launcher


@lru_cache(maxsize=None)
def cell_offsets(spec, real=np.float32):
    DIM = spec.DIM

    @njit
    def cell_offsets_main(k, params, cell_pyramid, cell_start, grid_status, layer_start):
        P = params[0]
        # [1] one invocation per cell of the grid's range (grid_range.glsl); outside it no cell holds a
        #     particle: a layer's first row is 0 before the range, n after it (the range's first cell writes those)
        c = grid_first(P) + k
        layers = int(P.grid_dim[2] if DIM == 3 else P.grid_dim[1])
        per_layer = int(P.cell_total) // layers
        if c == grid_first(P):
            for layer in range(grid_first(P) // per_layer):
                layer_start[layer] = 0
            for layer in range(grid_end(P) // per_layer, layers):
                layer_start[layer] = P.n
        if c >= grid_end(P):
            return
        # [2] from the top level down: at level l the cell's ancestor is c / 8^l, and every
        #     sibling before that ancestor (same parent) counts particles that come before c
        start = 0
        for l in range(int(P.levels) - 1, -1, -1):
            ancestor = c >> (3 * l)
            offset = level_offset(P.cell_total, l)
            for s in range(ancestor & ~7, ancestor):
                start += cell_pyramid[offset + s]
        cell_start[c] = start
        # [3] a layer's first cell: the layer's start
        if c % per_layer == 0:
            layer_start[c // per_layer] = start
        # [4] the top of the pyramid must hold every particle exactly once; a mismatch is counted
        #     in grid_status[2] (an overflow or a lost particle: never silently accepted)
        if c == grid_first(P) and cell_pyramid[level_offset(P.cell_total, P.levels)] != P.n:
            grid_status[2] += 1

    return launcher(cell_offsets_main)
