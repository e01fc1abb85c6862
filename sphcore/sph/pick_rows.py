"""Between two steps of a rank of sphcore.parallel: the rows of its slab each other rank needs for the next step,
packed for the exchange, one invocation per row: a migrant (its layer in the other's slab) from the entry's first
slot on, a halo row (within the halo's width of the slab) from its last down; into the sort's scratch buffers
(Verlet's half-step velocity into particle_a). The shader says more.

Mirror of shaders/sph/pick_rows.comp: same names, same statement order, same step labels. The atomics become plain
updates in a sequential launch (invocations in index order).
"""
from functools import lru_cache

import numpy as np
from numba import njit

from sphcore.sph.cells import cells
from sphcore.workgroups import launcher


@lru_cache(maxsize=None)
def pick_rows(spec, real=np.float32):
    DIM, VERLET = spec.DIM, spec.VERLET
    cell_of = cells(spec, real).cell_of

    @njit
    def pick_rows_main(i, params, particle_x, particle_v, particle_rho, particle_id, particle_vh, scratch_x,
                       scratch_v, scratch_id, scratch_rho, particle_a, pick_table, pick_bounds, pick_count):
        P = params[0]
        # [1] one invocation per row
        if i >= P.n:
            return
        # [2] the row's layer along the slab axis, as the sort finds it (clamped into the grid), and its coordinate
        axis = DIM - 1
        x_x = particle_x[i, 0]
        x_y = particle_x[i, 1]
        x_z = particle_x[i, 2]
        layer = min(max(cell_of(P, x_x, x_y, x_z)[axis], 0), int(P.grid_dim[axis]) - 1)
        coordinate = particle_x[i, axis]
        # [3] each rank the row may go to (pick_table[0, 0] entries: rows (first, end, slab's first layer, end
        #     layer), then (first slot, slots)), and the slot it takes there
        entries = np.int64(pick_table[0, 0])  # (int64 throughout: numba takes uint32 with int64 as float64)
        for e in range(entries):
            if i < np.int64(pick_table[1 + 2 * e, 0]) or i >= np.int64(pick_table[1 + 2 * e, 1]):
                continue
            if layer >= np.int64(pick_table[1 + 2 * e, 2]) and layer < np.int64(pick_table[1 + 2 * e, 3]):
                k = np.int64(pick_table[2 + 2 * e, 0]) + np.int64(pick_count[2 * e])
                pick_count[2 * e] += 1
            elif coordinate >= real(pick_bounds[e, 0]) and coordinate < real(pick_bounds[e, 1]):
                k = (np.int64(pick_table[2 + 2 * e, 0]) + np.int64(pick_table[2 + 2 * e, 1]) - 1
                     - np.int64(pick_count[2 * e + 1]))
                pick_count[2 * e + 1] += 1
            else:
                continue
            # [4] the row packed into slot k
            for c in range(4):  # (a vec4)
                scratch_x[k, c] = particle_x[i, c]
            for c in range(4):  # (a vec4)
                scratch_v[k, c] = particle_v[i, c]
            scratch_id[k] = particle_id[i]
            scratch_rho[k] = particle_rho[i]
            if VERLET:
                for c in range(4):  # (a vec4)
                    particle_a[k, c] = particle_vh[i, c]

    return launcher(pick_rows_main, parallel=False)
