"""Each particle finds its cell and takes a slot in it by an atomic count, one invocation per
particle. The slot order depends on scheduling; sort_cells makes it deterministic.

Mirror of shaders/sph/count_cells.comp: same names, same statement order, same step labels.
The atomics become plain updates in a sequential launch (invocations in index order).
"""
from functools import lru_cache

import numpy as np
from numba import njit

from sphcore.sph.cells import CELL_LIMIT, cells
from sphcore.workgroups import launcher



@lru_cache(maxsize=None)
def count_cells(spec, real=np.float32):
    WALLS = spec.WALLS
    cell_of = cells(spec, real).cell_of
    cell_index = cells(spec, real).cell_index

    @njit
    def count_cells_main(i, params, particle_x, particle_id, particle_cell, particle_slot, cell_pyramid,
                         grid_status):
        P = params[0]
        # [1] one invocation per particle
        if i >= P.n:
            return
        # [2] cell coordinates; a particle outside the grid's range (past a wall, beyond the hashed
        #     range, or not finite) is counted in grid_status[0] and the lowest such id kept in
        #     grid_status[1]; it still gets a cell (0), so no particle is ever dropped
        x_x = particle_x[i, 0]
        x_y = particle_x[i, 1]
        x_z = particle_x[i, 2]
        c_x, c_y, c_z = cell_of(P, x_x, x_y, x_z)
        f_x = np.floor((x_x - P.box_min[0]) * P.inv_cell)
        f_y = np.floor((x_y - P.box_min[1]) * P.inv_cell)
        f_z = np.floor((x_z - P.box_min[2]) * P.inv_cell)
        if WALLS:
            inside = (f_x >= real(0.0) and f_y >= real(0.0) and f_z >= real(0.0)
                      and f_x <= real(P.grid_dim[0]) and f_y <= real(P.grid_dim[1]) and f_z <= real(P.grid_dim[2]))
        else:
            inside = abs(f_x) < real(CELL_LIMIT) and abs(f_y) < real(CELL_LIMIT) and abs(f_z) < real(CELL_LIMIT)
        if not inside:
            grid_status[0] += 1
            grid_status[1] = min(grid_status[1], particle_id[i])
            c_x, c_y, c_z = 0, 0, 0
        # [3] a particle exactly on the upper wall belongs to the last cell
        if WALLS:
            c_x = min(c_x, int(P.grid_dim[0]) - 1)
            c_y = min(c_y, int(P.grid_dim[1]) - 1)
            c_z = min(c_z, int(P.grid_dim[2]) - 1)
        cell = cell_index(P, c_x, c_y, c_z)
        # [4] count, and take the next free slot of the cell
        particle_cell[i] = cell
        particle_slot[i] = cell_pyramid[cell]
        cell_pyramid[cell] += 1

    return launcher(count_cells_main, parallel=False)
