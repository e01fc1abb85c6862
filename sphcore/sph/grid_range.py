"""The cells the grid's cell stages take (params.glsl: P.cells_first .. cells_end - 1, a rank's; cells_end 0: every
cell): invocation k of such a stage takes cell grid_first(P) + k (backends.dispatch_size dispatches the range).

Mirror of shaders/sph/grid_range.glsl: same names, same statements.
"""
from numba import njit


@njit
def grid_first(P):
    return int(P.cells_first) if P.cells_end > 0 else 0


@njit
def grid_end(P):
    return int(P.cells_end) if P.cells_end > 0 else int(P.cell_total)
