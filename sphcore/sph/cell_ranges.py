"""The grid's cell ranges (cells.py: range_count, range_cells) as ranges of sorted particles, for the scans
(walk.py, sample_gauges.py). GLSL reads cell_start and cell_pyramid as buffers the including shader declares;
here they are arguments, after the parameter block.

Mirror of shaders/sph/cell_ranges.glsl: same names, same statements; the out parameters start and end are
returned after the result.
"""
from functools import lru_cache

import numpy as np
from numba import njit

from sphcore.sph.cells import cells


@lru_cache(maxsize=None)
def cell_ranges(spec, real=np.float32):
    GRID = spec.GRID
    range_cells = cells(spec, real).range_cells

    @njit
    def cell_range(P, cell_pyramid, cell_start, base_x, base_y, base_z, k):
        """(inside, start, end): sorted particles [start, end) of range k around cell `base`, or every particle
        without the grid; inside False where the range is outside the box."""
        start = 0
        end = int(P.n)
        if not GRID:
            return True, start, end
        inside, first, last = range_cells(P, base_x, base_y, base_z, k)
        if not inside:
            return False, start, end
        start = int(cell_start[first])
        end = int(cell_start[last]) + int(cell_pyramid[last])
        return True, start, end

    return cell_range
