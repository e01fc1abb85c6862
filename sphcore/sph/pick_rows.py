"""After a step of a rank of sphcore.parallel (the step's last stage, or alone before the exchange; D.level 1: before
integrate, each row taken as integrate will store it): the rows of its slab each other rank needs for the next step,
packed for the exchange, one invocation per row: a migrant (its layer in the other's slab) into the entry's first
zone of slots, a halo row (within the halo's width of the slab) into its second; into the sort's scratch buffers and
scratch_vh (Verlet's half-step velocity). The shader says more.

Mirror of shaders/sph/pick_rows.comp: same names, same statement order, same step labels. The atomics become plain
updates in a sequential launch (invocations in index order).
"""
from functools import lru_cache

import numpy as np
from numba import njit

from sphcore.sph.band_rows import band_row_at
from sphcore.sph.cells import cells
from sphcore.sph.integrate_row import integrate_row
from sphcore.sph.pick_table import pick_table_functions
from sphcore.workgroups import launcher


@lru_cache(maxsize=None)
def pick_rows(spec, real=np.float32):
    DIM, VERLET, BODIES, ADAPTIVE_DT = spec.DIM, spec.VERLET, spec.BODIES, spec.ADAPTIVE_DT
    cell_of = cells(spec, real).cell_of
    zone_of = pick_table_functions(spec).zone_of
    integrated = integrate_row(spec, real)
    NO_SHIFT = (real(0.0), real(0.0), real(0.0), real(0.0))

    @njit
    def pick_rows_main(i, params, particle_x, particle_v, particle_a, particle_rho, particle_id, particle_vh,
                       obstacle_box, time_state, scratch_x, scratch_v, scratch_id, scratch_rho, scratch_vh, pick_table,
                       pick_bounds, pick_count, layer_start, band_rows):
        P = params[0]
        # [1] one invocation per row an entry reads (band_rows.py: an indirect dispatch of as many), entry after entry
        found, i, e = band_row_at(i, band_rows)
        if not found or i >= P.n:
            return
        # [2] the row as it is, or at D.level 1 as integrate will store it (a body's wall particle stays)
        x_x, x_y, x_z, x_w = particle_x[i, 0], particle_x[i, 1], particle_x[i, 2], particle_x[i, 3]
        v_x, v_y, v_z, v_w = particle_v[i, 0], particle_v[i, 1], particle_v[i, 2], particle_v[i, 3]
        vh_x, vh_y, vh_z, vh_w = particle_vh[i, 0], particle_vh[i, 1], particle_vh[i, 2], particle_vh[i, 3]
        if P.level == 1 and not (BODIES and particle_id[i] >= P.fluid_count):
            # (at a fixed dt before choose_dt: time_state's dt is the last step's; with an adaptive dt after it)
            dt = time_state[0, 0] if ADAPTIVE_DT else P.dt
            dt_prev = (time_state[0, 1] if ADAPTIVE_DT else time_state[0, 0]) if VERLET else np.float32(0.0)
            (x_x, x_y, x_z), (v_x, v_y, v_z), stepped_vh = integrated(
                P, i, dt, dt_prev, NO_SHIFT, particle_x, particle_v, particle_a, particle_vh, obstacle_box)
            x_w = v_w = real(0.0)
            if VERLET:
                (vh_x, vh_y, vh_z), vh_w = stepped_vh, real(0.0)
        # [3] its layer along the slab axis, as the sort finds it (clamped into the grid), and its coordinate
        axis = DIM - 1
        layer = min(max(cell_of(P, x_x, x_y, x_z)[axis], 0), int(P.grid_dim[axis]) - 1)
        coordinate = (x_x, x_y, x_z)[axis]
        # [4] whether its entry's rank (pick_table.glsl) takes it, and the slot it takes there: its entry's zones
        #     follow those of the entries before it (int64 throughout: numba takes uint32 with int64 as float64)
        slot = 0
        for f in range(e):
            slot += 2 * zone_of(np.int64(band_rows[1 + f, 1]))
        zone = zone_of(np.int64(band_rows[1 + e, 1]))
        if layer >= np.int64(pick_table[1 + e, 2]) and layer < np.int64(pick_table[1 + e, 3]):
            k = slot + np.int64(pick_count[2 * e])
            pick_count[2 * e] += 1
        elif coordinate >= real(pick_bounds[e, 0]) and coordinate < real(pick_bounds[e, 1]):
            k = slot + zone + np.int64(pick_count[2 * e + 1])
            pick_count[2 * e + 1] += 1
        else:
            return
        if slot + 2 * zone > P.n:
            return
        # [5] the row packed into slot k
        scratch_x[k, 0], scratch_x[k, 1], scratch_x[k, 2], scratch_x[k, 3] = x_x, x_y, x_z, x_w
        scratch_v[k, 0], scratch_v[k, 1], scratch_v[k, 2], scratch_v[k, 3] = v_x, v_y, v_z, v_w
        scratch_id[k] = particle_id[i]
        scratch_rho[k] = particle_rho[i]
        if VERLET:
            scratch_vh[k, 0], scratch_vh[k, 1], scratch_vh[k, 2], scratch_vh[k, 3] = vh_x, vh_y, vh_z, vh_w

    return launcher(pick_rows_main, parallel=False)
