"""The scene's gauges, one invocation per gauge, after compute_forces and before choose_dt (the state and the
time of the step's start): a sample at the first step at or past each multiple of a gauge's interval. pressure,
velocity, density: Shepard-normalised SPH interpolation at a point over the fluid within h (DualSPHysics'
MeasureTool, GaugeVel), no mirror images; height: where the mass sum along the vertical line falls below
rho_0 / 2 (DualSPHysics' GaugeSwl); force, moment: m sum a over a body's particles, each cell layer's in buffer
order, then the layers' in layer order. On a rank of sphcore.parallel, what lies in its slab (a force: each of its
slab's layers' sums in gauge_layers as well); a sample it took nothing of has the time -1 (the shader says more).

Mirror of shaders/sph/sample_gauges.comp: same names, same statement order, same step labels. A GLSL vec3
local `v` is `v_x, v_y, v_z` here; the time's float32 arithmetic is numba's float32, as the shader's.
"""
from functools import lru_cache

import numpy as np
from numba import njit

from sphcore.gauges import LAYER_SLOTS
from sphcore.sph.cell_ranges import cell_ranges
from sphcore.sph.cells import cells
from sphcore.sph.kernels import kernels
from sphcore.workgroups import launcher

f32 = np.float32
PRESSURE, VELOCITY, DENSITY, HEIGHT, FORCE, MOMENT = range(6)  # sphcore.gauges.QUANTITIES


@lru_cache(maxsize=None)
def sample_gauges(spec, real=np.float32):
    BODIES, DIM, GRID = spec.BODIES, spec.DIM, spec.GRID
    cell_of = cells(spec, real).cell_of
    range_count = cells(spec, real).range_count
    cell_range = cell_ranges(spec, real)
    kernel_w = kernels(spec, real).kernel_w

    @njit
    def reached(t, target):
        """Whether time t is at or past `target`, within 1e-6 of it (runner.reached)."""
        least = target - f32(1e-6) * target
        return t >= least

    @njit
    def point_sums(P, x_x, x_y, x_z, particle_x, particle_v, particle_rho, particle_p, particle_id, cell_pyramid,
                   cell_start):
        """Sums over the fluid within h of point x: (sum V W, sum V W p, sum V W rho, sum W) and sum V W v; the
        bodies' wall particles left out."""
        sums_x = sums_y = sums_z = sums_w = real(0.0)
        sum_v_x = sum_v_y = sum_v_z = real(0.0)
        base_x, base_y, base_z = cell_of(P, x_x, x_y, x_z)
        for k in range(range_count()):
            inside, start, end = cell_range(P, cell_pyramid, cell_start, base_x, base_y, base_z, k)
            if not inside:
                continue  # (cell_ranges.glsl)
            for j in range(start, end):
                r_x = x_x - particle_x[j, 0]
                r_y = x_y - particle_x[j, 1]
                r_z = x_z - particle_x[j, 2]
                r2 = r_x * r_x + r_y * r_y + r_z * r_z
                if r2 >= P.h2 or (BODIES and particle_id[j] >= P.fluid_count):
                    continue
                w = kernel_w(P, r2)
                vw = w / particle_rho[j]
                sums_x += vw
                sums_y += vw * particle_p[j]
                sums_z += vw * particle_rho[j]
                sums_w += w
                sum_v_x += vw * particle_v[j, 0]
                sum_v_y += vw * particle_v[j, 1]
                sum_v_z += vw * particle_v[j, 2]
        return sums_x, sums_y, sums_z, sums_w, sum_v_x, sum_v_y, sum_v_z

    @njit
    def in_slab(P, x_x, x_y, x_z):
        """Whether point x lies in this rank's slab: the layer of its cell along the slab axis, clamped into the
        grid, among the cells owned_first .. owned_end - 1; every point where owned_end is 0."""
        if P.owned_end == 0:
            return True
        axis = DIM - 1
        layer = min(max(cell_of(P, x_x, x_y, x_z)[axis], 0), int(P.grid_dim[axis]) - 1)
        first = layer * (int(P.cell_total) // int(P.grid_dim[axis]))
        return first >= P.owned_first and first < P.owned_end

    @njit
    def surface_height(P, x_x, x_y, x_z, step, up, particle_x, particle_v, particle_rho, particle_p, particle_id,
                       cell_pyramid, cell_start):
        """(height, seen): the free surface's elevation above foot x on the vertical line, along axis `up` (0
        where the mass sum never reaches rho_0 / 2), of the points in the slab and the one below each (in_slab);
        seen 0 where the slab holds no point of the line, 1 where the surface is not found there, 2 where it is."""
        x_up = x_x if up == 0 else x_y if up == 1 else x_z
        half_rest = real(0.5) * real(P.rest_density)
        top = real(P.box_max[up])
        height = real(0.0)
        before = real(0.0)
        level = x_up
        seen = 0
        k = 0
        while level <= top:
            at_x, at_y, at_z = x_x, x_y, x_z
            at_x, at_y, at_z = (level if up == 0 else at_x), (level if up == 1 else at_y), (level if up == 2 else at_z)
            following = x_up + real(k + 1) * step
            above_x, above_y, above_z = x_x, x_y, x_z
            above_x, above_y, above_z = ((following if up == 0 else above_x), (following if up == 1 else above_y),
                                         (following if up == 2 else above_z))
            mine = in_slab(P, at_x, at_y, at_z)
            if mine or (following <= top and in_slab(P, above_x, above_y, above_z)):
                mass = real(P.density_coef) * point_sums(P, at_x, at_y, at_z, particle_x, particle_v, particle_rho,
                                                         particle_p, particle_id, cell_pyramid, cell_start)[3]
                # a fall below half the rest density between the last point and this one: the surface (the highest)
                if mine and k > 0 and before >= half_rest and mass < half_rest:
                    height = level - step + step * (before - half_rest) / (before - mass) - x_up
                    seen = 2
                if mine:
                    seen = max(seen, 1)
                before = mass
            level = following
            k += 1
        return height, seen

    @njit
    def sample_gauges_main(g, params, particle_x, particle_v, particle_a, particle_rho, particle_p, particle_id,
                           cell_pyramid, cell_start, time_state, gauge_table, gauge_state, gauge_samples,
                           layer_start, gauge_layers):
        P = params[0]
        # [1] one invocation per gauge
        if g >= len(gauge_state) // 2:
            return
        # (a height's axis in place of the body's first id: surface_height)
        quantity, body_first, body_count, slots = (int(gauge_state[2 * g, 0]), int(gauge_state[2 * g, 1]),
                                                   int(gauge_state[2 * g, 2]), int(gauge_state[2 * g, 3]))
        next_multiple, taken = int(gauge_state[2 * g + 1, 0]), int(gauge_state[2 * g + 1, 1])
        if slots == 0:
            return  # (no gauge: a state without [[gauges]])
        # [2] due? the time at the step's start against the next multiple of the interval (runner.reached)
        t = time_state[0, 2] + time_state[0, 3]
        interval = gauge_table[2 * g, 3]
        if not reached(t, f32(next_multiple) * interval):
            return
        # [3] the sample
        x_x, x_y, x_z = real(gauge_table[2 * g, 0]), real(gauge_table[2 * g, 1]), real(gauge_table[2 * g, 2])
        aux_x, aux_y, aux_z = real(gauge_table[2 * g + 1, 0]), real(gauge_table[2 * g + 1, 1]), \
            real(gauge_table[2 * g + 1, 2])
        value_x = value_y = value_z = real(0.0)
        sampled = quantity >= FORCE or in_slab(P, x_x, x_y, x_z)  # (a height's: as its line finds)
        if quantity <= DENSITY and sampled:
            sums_x, sums_y, sums_z, sums_w, sum_v_x, sum_v_y, sum_v_z = point_sums(
                P, x_x, x_y, x_z, particle_x, particle_v, particle_rho, particle_p, particle_id, cell_pyramid, cell_start)
            if sums_x > real(0.0):
                if quantity == PRESSURE:
                    value_x = sums_y / sums_x
                if quantity == VELOCITY:
                    value_x, value_y, value_z = sum_v_x / sums_x, sum_v_y / sums_x, sum_v_z / sums_x
                if quantity == DENSITY:
                    value_x = sums_z / sums_x
        if quantity == HEIGHT:
            value_x, seen = surface_height(P, x_x, x_y, x_z, aux_x, body_first, particle_x, particle_v, particle_rho,
                                           particle_p, particle_id, cell_pyramid, cell_start)
            value_y = real(1.0) if seen == 2 else real(0.0)
            sampled = seen > 0
        if quantity >= FORCE:
            # a sum over each cell layer's rows, the layers' sums added in layer order; on a rank each layer's sum
            # also into the sample's row of gauge_layers (its slab's layers'; 0 for the others)
            force_x = force_y = force_z = real(0.0)
            moment_x = moment_y = moment_z = real(0.0)
            layers = int(P.grid_dim[DIM - 1]) if GRID else 1
            per_layer = int(P.cell_total) // layers
            row = (g * LAYER_SLOTS + taken % LAYER_SLOTS) * layers
            for layer in range(layers):
                layer_force_x = layer_force_y = layer_force_z = real(0.0)
                layer_moment_x = layer_moment_y = layer_moment_z = real(0.0)
                mine = P.owned_end == 0 or (P.owned_first <= layer * per_layer < P.owned_end)
                first = int(layer_start[layer]) if GRID else 0
                end = int(layer_start[layer + 1]) if layer + 1 < layers else int(P.n)
                for i in range(first, end if mine else first):
                    if (int(particle_id[i]) - body_first) & 0xFFFFFFFF >= body_count:
                        continue  # (not the body's: unsigned, below first too)
                    a_x, a_y, a_z = particle_a[i, 0], particle_a[i, 1], particle_a[i, 2]
                    r_x, r_y, r_z = particle_x[i, 0] - aux_x, particle_x[i, 1] - aux_y, particle_x[i, 2] - aux_z
                    layer_force_x += a_x
                    layer_force_y += a_y
                    layer_force_z += a_z
                    layer_moment_x += r_y * a_z - r_z * a_y
                    layer_moment_y += r_z * a_x - r_x * a_z
                    layer_moment_z += r_x * a_y - r_y * a_x
                force_x += layer_force_x
                force_y += layer_force_y
                force_z += layer_force_z
                moment_x += layer_moment_x
                moment_y += layer_moment_y
                moment_z += layer_moment_z
                if P.owned_end > 0:
                    if quantity == FORCE:
                        gauge_layers[row + layer, 0] = layer_force_x
                        gauge_layers[row + layer, 1] = layer_force_y
                        gauge_layers[row + layer, 2] = layer_force_z
                    else:
                        gauge_layers[row + layer, 0] = layer_moment_x
                        gauge_layers[row + layer, 1] = layer_moment_y
                        gauge_layers[row + layer, 2] = layer_moment_z
                    gauge_layers[row + layer, 3] = real(0.0)
            mass = real(gauge_table[2 * g + 1, 3])
            if quantity == FORCE:
                value_x, value_y, value_z = mass * force_x, mass * force_y, mass * force_z
            else:
                value_x, value_y, value_z = mass * moment_x, mass * moment_y, mass * moment_z
        # [4] store: the row at the ring's next slot, the count, and the next multiple past t
        row = g * slots + taken % slots
        gauge_samples[row, 0] = real(time_state[0, 2]) + real(time_state[0, 3]) if sampled else real(-1.0)
        gauge_samples[row, 1] = value_x
        gauge_samples[row, 2] = value_y
        gauge_samples[row, 3] = value_z
        following = max(next_multiple + 1, int(t / interval))
        while reached(t, f32(following) * interval):
            following += 1
        gauge_state[2 * g + 1, 0] = following
        gauge_state[2 * g + 1, 1] = taken + 1
        gauge_state[2 * g + 1, 2] = 0
        gauge_state[2 * g + 1, 3] = 0

    return launcher(sample_gauges_main)
