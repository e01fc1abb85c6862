"""DFSPH's residual r_i of solve D.level (dfsph.py), one invocation per particle: the density ratio's
rate d_i = sum_j V (v_i - v_j) . grad W_ij over its neighbour list (walk.py: walk_list), each gradient as
dfsph_factor computes it (stored in neighbour_gradients with GRADIENTS), summed as v_i . G_i - sum_j V v_j . grad W_ij with dfsph_factor's
G_i = sum_j V grad W_ij (particle_gradient_sum); divergence-free solve
r_i = max(d_i, 0), constant-density solve r_i = max(rho_i / rho_0 + dt d_i* - 1, 0) with v* = v + dt a (in
scratch_v: dfsph_predict, dfsph_velocity);
each work group's residuals summed in order into dfsph_partial; the last work group to finish runs the
solve's convergence test (dfsph_check). Dispatched indirectly: no work groups once the solve has stopped.

Mirror of shaders/sph/dfsph_residual.comp: same names, same statement order, same step labels.
A GLSL vec3 local `v` is `v_x, v_y, v_z` here. The shader's barriers split it into phases, so `launch`
runs, per work group, one local loop over the invocations per phase, with the group's shared arrays as
scratch (STYLE.md); the first phase is `dfsph_residual_main`, which returns the invocation's residual (the
value it leaves in shared memory). The shader elects the last group to finish by an atomic count; here
the groups run in a parallel loop, and the last group's phases (the check) run once after it, which is
where the count puts them. Whichever group the shader elects, it computes the same.
"""
from functools import lru_cache

import numpy as np
from numba import njit, prange

from sphcore.numba_cache import cached
from sphcore.sph.cells import cells
from sphcore.sph.dfsph import SOLVE_DENSITY
from sphcore.sph.dfsph_check import dfsph_check
from sphcore.sph.neighbour_list import neighbour_list
from sphcore.sph.obstacles import obstacles
from sphcore.sph.walk import list_walk


@lru_cache(maxsize=None)
def dfsph_residual(spec, real=np.float32):
    MAX_NEIGHBOURS = spec.MAX_NEIGHBOURS
    near_walls = cells(spec, real).near_walls
    near_obstacles = obstacles(spec, real).near_obstacles
    listed_gradient = neighbour_list(spec, real).listed_gradient
    dfsph_check_share = dfsph_check(spec, real).dfsph_check_share
    dfsph_check_decide = dfsph_check(spec, real).dfsph_check_decide

    @njit(inline="always")  # (numba inlines it into its caller: no tuple crosses a call)
    def list_entry(own, state, i, slot, chunk):
        """One entry of i's list (walk.py: walk_list hands over each slot): the neighbour j, or its image across the
        walls whose bits are set in `image`, and g = V grad_i W_ik (neighbour_list.py); the neighbour's velocity (an
        image's mirrored on the flipped axes) and V (v_i - v_k) . grad_i W_ik, less v_i's part (in d from the start).
        Returns (chunk, d)."""
        P, particle_x, particle_v, particle_vstar, neighbours, neighbour_gradients, xi_x, xi_y, xi_z, wall_x, wall_y, \
            wall_z, inward_x, inward_y, inward_z, density = own
        d = state
        chunk, j, image, g_x, g_y, g_z = listed_gradient(P, particle_x, neighbours, neighbour_gradients, i, slot, chunk,
                                                         xi_x, xi_y, xi_z, wall_x, wall_y, wall_z, inward_x, inward_y,
                                                         inward_z)
        vk_x = particle_vstar[j, 0] if density else particle_v[j, 0]
        vk_y = particle_vstar[j, 1] if density else particle_v[j, 1]
        vk_z = particle_vstar[j, 2] if density else particle_v[j, 2]
        if image != 0:
            vk_x = -vk_x if (image & 1) != 0 else vk_x
            vk_y = -vk_y if (image & 2) != 0 else vk_y
            vk_z = -vk_z if (image & 4) != 0 else vk_z
        d -= vk_x * g_x + vk_y * g_y + vk_z * g_z
        return chunk, d

    walk_list = list_walk(list_entry)

    @njit
    def dfsph_residual_main(i, params, particle_x, particle_v, particle_vstar, particle_rho, obstacle_box, time_state,
                            particle_residual, neighbours, neighbour_count, neighbour_gradients,
                            particle_gradient_sum):
        P = params[0]
        D = params[0]  # (the dispatch's push constants: on numba, fields of the same record)
        # [1] one invocation per particle (none once the solve has stopped: its dispatch is indirect); every
        #     invocation of the group reaches the barrier, with a residual of 0 past the last particle
        solve = int(D.level)
        residual = real(0.0)
        if i >= P.n:
            return residual
        # [2] the velocity the solve corrects: v (divergence-free), v* = v + dt a (constant density)
        dt = real(time_state[0, 0])
        density = solve == SOLVE_DENSITY
        xi_x = particle_x[i, 0]
        xi_y = particle_x[i, 1]
        xi_z = particle_x[i, 2]
        vi_x = particle_vstar[i, 0] if density else particle_v[i, 0]
        vi_y = particle_vstar[i, 1] if density else particle_v[i, 1]
        vi_z = particle_vstar[i, 2] if density else particle_v[i, 2]
        # [3] the walls and obstacle faces the images are mirrored across, as in compute_density
        mirrored, wall_x, wall_y, wall_z = near_walls(P, xi_x, xi_y, xi_z)
        mirrored, wall_x, wall_y, wall_z, inward_x, inward_y, inward_z = near_obstacles(
            P, obstacle_box, xi_x, xi_y, xi_z, mirrored, wall_x, wall_y, wall_z)
        # [4] d_i over the neighbour list (dfsph_factor): every other particle and every image within h
        #     (walk.py: walk_list, list_entry above)
        sum_g_x = particle_gradient_sum[i, 0]
        sum_g_y = particle_gradient_sum[i, 1]
        sum_g_z = particle_gradient_sum[i, 2]
        d = vi_x * sum_g_x + vi_y * sum_g_y + vi_z * sum_g_z
        count = min(int(neighbour_count[i]), MAX_NEIGHBOURS)
        d = walk_list(i, count, (P, particle_x, particle_v, particle_vstar, neighbours, neighbour_gradients, xi_x, xi_y,
                                 xi_z, wall_x, wall_y, wall_z, inward_x, inward_y, inward_z, density), d)
        # [5] the residual: compression only. The constant-density one is `precise` in the shader (no
        #     reassociation, no fused multiply-add: the order written here; issue 30)
        residual = max(d, real(0.0))
        if density:
            compression = particle_rho[i] / real(P.rest_density) + dt * d - real(1.0)
            residual = max(compression, real(0.0))
        # [6] store
        particle_residual[i] = residual
        return residual

    @njit
    def dfsph_residual_partial(group, local_size, dfsph_partial, s_residual):
        # [7] invocation 0: the group's residuals in order, its part of the solve's error; made visible, then
        #     the group counted as finished: the last one to finish (the count's old value one short of the
        #     groups) runs the check. Which group that is varies; what it computes does not
        total = real(0.0)
        for k in range(local_size):
            total += s_residual[k]
        dfsph_partial[group] = total

    @njit(parallel=True, error_model="numpy")
    def launch(n_groups, local_size, params, particle_x, particle_v, particle_vstar, particle_rho, obstacle_box,
               time_state, particle_residual, dfsph_partial, neighbours, neighbour_count, neighbour_gradients,
               control, dfsph_state, dfsph_history, particle_gradient_sum):
        groups = (int(params[0].n) + local_size - 1) // local_size
        for group in prange(n_groups):
            s_residual = np.empty(local_size, real)  # the group's shared memory
            for lid in range(local_size):
                s_residual[lid] = dfsph_residual_main(group * local_size + lid, params, particle_x, particle_v,
                                                      particle_vstar, particle_rho, obstacle_box, time_state,
                                                      particle_residual, neighbours, neighbour_count,
                                                      neighbour_gradients, particle_gradient_sum)
            # (barrier)
            dfsph_residual_partial(group, local_size, dfsph_partial, s_residual)
        if n_groups == 0:
            return
        # (barrier)
        # [8] the last group: the convergence test over every group's sum (dfsph_check.glsl), each
        #     invocation its share, then invocation 0 the error and the stop; the count reset for the next
        s_sum = np.empty(local_size, real)  # the last group's shared memory
        for lid in range(local_size):
            s_sum[lid] = dfsph_check_share(lid, groups, local_size, dfsph_partial)
        # (barrier)
        dfsph_check_decide(int(params[0].level), local_size, params, time_state, control, dfsph_state,
                           dfsph_history, s_sum)

    return cached(launch)
