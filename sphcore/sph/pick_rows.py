"""After a step of a rank of sphcore.parallel (the step's last stage, or alone before the exchange): the rows of its
slab each other rank needs for the next step, packed for the exchange, one invocation per row: a migrant (its layer in
the other's slab) into the entry's first zone of slots, a halo row (within the halo's width of the slab) into its
second; into the sort's scratch buffers and scratch_vh (Verlet's half-step velocity). The shader says more.

Mirror of shaders/sph/pick_rows.comp: same names, same statement order, same step labels. The atomics become plain
updates in a sequential launch (invocations in index order).
"""
from functools import lru_cache

import numpy as np
from numba import njit

from sphcore.sph.cells import cells
from sphcore.workgroups import launcher

PICK_ALIGN = 4  # rows: 16 bytes of a 4-byte buffer


@njit
def row_of(layer, layers, held, layer_start):
    """The first row the last sort gave layer `layer` (the rows held past the last layer)."""
    return np.int64(layer_start[layer]) if layer < layers else held


@lru_cache(maxsize=None)
def pick_rows(spec, real=np.float32):
    DIM, VERLET = spec.DIM, spec.VERLET
    cell_of = cells(spec, real).cell_of

    @njit
    def pick_rows_main(i, params, particle_x, particle_v, particle_rho, particle_id, particle_vh, scratch_x,
                       scratch_v, scratch_id, scratch_rho, scratch_vh, pick_table, pick_bounds, pick_count,
                       layer_start):
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
        # [3] each rank the row may go to (pick_table[0]: the entries, the rows held; then an entry's row: the layers
        #     whose rows it may need (first, end), its slab's first layer and end layer), and the slot it takes there
        entries = np.int64(pick_table[0, 0])  # (int64 throughout: numba takes uint32 with int64 as float64)
        held = np.int64(pick_table[0, 1])
        layers = np.int64(P.grid_dim[axis])
        base = 0
        for e in range(entries):
            first = row_of(np.int64(pick_table[1 + e, 0]), layers, held, layer_start)
            slots = row_of(np.int64(pick_table[1 + e, 1]), layers, held, layer_start) - first
            zone = (slots + PICK_ALIGN - 1) // PICK_ALIGN * PICK_ALIGN
            slot = base
            base += 2 * zone
            if i < first or i >= first + slots:
                continue
            if layer >= np.int64(pick_table[1 + e, 2]) and layer < np.int64(pick_table[1 + e, 3]):
                k = slot + np.int64(pick_count[2 * e])
                pick_count[2 * e] += 1
            elif coordinate >= real(pick_bounds[e, 0]) and coordinate < real(pick_bounds[e, 1]):
                k = slot + zone + np.int64(pick_count[2 * e + 1])
                pick_count[2 * e + 1] += 1
            else:
                continue
            if slot + 2 * zone > P.n:
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
                    scratch_vh[k, c] = particle_vh[i, c]

    return launcher(pick_rows_main, parallel=False)
