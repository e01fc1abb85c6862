"""One Jacobi update of DFSPH's solve D.level (dfsph.py), one invocation per particle: the change
-sum_j V (s_i + s_j) grad W_ij over its neighbour list (walk.py: walk_list), each gradient as dfsph_factor computes it (stored in
neighbour_gradients with GRADIENTS), s_j = alpha_j r_j (divergence-free)
or alpha_j r_j / dt^2 (constant density), added to the velocity (divergence-free) or to the acceleration,
with the pressure accumulated and v* = v + dt a kept in scratch_v for the next residual (constant density,
dfsph_predict). Dispatched indirectly: no work groups once the solve has stopped
(dfsph_check); invocation 0 counts the update.

Mirror of shaders/sph/dfsph_velocity.comp: same names, same statement order, same step labels.
A GLSL vec3 local `v` is `v_x, v_y, v_z` here.
"""
from functools import lru_cache

import numpy as np
from numba import njit

from sphcore.sph.cells import cells
from sphcore.sph.dfsph import CONTROL_ITERATIONS, SOLVE_DIVERGENCE, SOLVE_WARM_START
from sphcore.sph.neighbour_list import neighbour_list
from sphcore.sph.obstacles import obstacles
from sphcore.sph.walk import list_walk
from sphcore.workgroups import launcher


@lru_cache(maxsize=None)
def dfsph_velocity(spec, real=np.float32):
    MAX_NEIGHBOURS = spec.MAX_NEIGHBOURS
    near_walls = cells(spec, real).near_walls
    near_obstacles = obstacles(spec, real).near_obstacles
    listed_gradient = neighbour_list(spec, real).listed_gradient

    @njit(inline="always")  # (numba inlines it into its caller: no tuple crosses a call)
    def list_entry(own, state, i, slot, chunk):
        """One entry of i's list (walk.py: walk_list hands over each slot): the neighbour j (or its image: the same
        s_j) and g = V grad_i W_ij (neighbour_list.py); -V (s_i + s_j) grad_i W_ij: away from a compressed
        neighbourhood. Returns (chunk, change)."""
        P, particle_x, particle_alpha, particle_residual, particle_kappa, neighbours, neighbour_gradients, xi_x, xi_y, \
            xi_z, wall_x, wall_y, wall_z, inward_x, inward_y, inward_z, warm, scale, si = own
        change_x, change_y, change_z = state
        chunk, j, image, g_x, g_y, g_z = listed_gradient(P, particle_x, neighbours, neighbour_gradients, i, slot, chunk,
                                                         xi_x, xi_y, xi_z, wall_x, wall_y, wall_z, inward_x, inward_y,
                                                         inward_z)
        sj = scale * particle_alpha[j] * particle_residual[j]
        if warm:
            kappa_j = particle_kappa[j]  # (read before the test: a select, not a branch that mispredicts)
            sj = kappa_j if particle_residual[j] > real(0.0) else real(0.0)
        t = si + sj
        change_x -= t * g_x
        change_y -= t * g_y
        change_z -= t * g_z
        return chunk, (change_x, change_y, change_z)

    walk_list = list_walk(list_entry)

    @njit
    def dfsph_velocity_main(i, params, particle_x, particle_v, particle_a, particle_rho, particle_p, obstacle_box,
                            time_state, particle_alpha, particle_residual, control, particle_kappa,
                            neighbours, neighbour_count, neighbour_gradients, particle_vstar):
        P = params[0]
        D = params[0]  # (the dispatch's push constants: on numba, fields of the same record)
        # [1] one invocation per particle (none once the solve has stopped: its dispatch is indirect);
        #     invocation 0 counts the update
        if i >= P.n:
            return
        solve = int(D.level)
        warm = solve == SOLVE_WARM_START  # the warm start: always, and not counted
        if not warm and i == 0:
            control[CONTROL_ITERATIONS + solve] += 1
        # [2] the stiffness scale: 1 (divergence-free), 1 / dt^2 (constant density); own stiffness s_i (warm
        #     start: the stiffness sum, particle_kappa, where the particle is compressed: residual > 0)
        dt = real(time_state[0, 0])
        scale = real(1.0) if solve == SOLVE_DIVERGENCE else real(1.0) / (dt * dt)
        si = scale * particle_alpha[i] * particle_residual[i]
        if warm:
            si = particle_kappa[i] if particle_residual[i] > real(0.0) else real(0.0)
        xi_x = particle_x[i, 0]
        xi_y = particle_x[i, 1]
        xi_z = particle_x[i, 2]
        # [3] the walls and obstacle faces the images are mirrored across, as in compute_density
        mirrored, wall_x, wall_y, wall_z = near_walls(P, xi_x, xi_y, xi_z)
        mirrored, wall_x, wall_y, wall_z, inward_x, inward_y, inward_z = near_obstacles(
            P, obstacle_box, xi_x, xi_y, xi_z, mirrored, wall_x, wall_y, wall_z)
        # [4] the change over the neighbour list (dfsph_factor): every other particle and every image within h
        #     (walk.py: walk_list, list_entry above)
        zero = real(0.0)
        count = min(int(neighbour_count[i]), MAX_NEIGHBOURS)
        change_x, change_y, change_z = walk_list(
            i, count, (P, particle_x, particle_alpha, particle_residual, particle_kappa, neighbours, neighbour_gradients,
                       xi_x, xi_y, xi_z, wall_x, wall_y, wall_z, inward_x, inward_y, inward_z, warm, scale, si),
            (zero, zero, zero))
        # [5] store: the velocity (divergence-free) or the acceleration, the stiffness sum and the pressure
        #     (constant density; only the warm start reads the sum of others, and it writes none)
        if solve == SOLVE_DIVERGENCE:
            particle_v[i, 0] = particle_v[i, 0] + change_x
            particle_v[i, 1] = particle_v[i, 1] + change_y
            particle_v[i, 2] = particle_v[i, 2] + change_z
            particle_v[i, 3] = real(0.0)
        else:
            a_x = particle_a[i, 0] + change_x
            a_y = particle_a[i, 1] + change_y
            a_z = particle_a[i, 2] + change_z
            particle_a[i, 0] = a_x
            particle_a[i, 1] = a_y
            particle_a[i, 2] = a_z
            particle_a[i, 3] = real(0.0)
            particle_vstar[i, 0] = particle_v[i, 0] + dt * a_x
            particle_vstar[i, 1] = particle_v[i, 1] + dt * a_y
            particle_vstar[i, 2] = particle_v[i, 2] + dt * a_z
            particle_vstar[i, 3] = real(0.0)
            rhoi = particle_rho[i]
            p = si * rhoi * rhoi / real(P.rest_density)
            if not warm:
                p += particle_p[i]
            particle_p[i] = p
            if not warm:
                particle_kappa[i] = p * real(P.rest_density) / (rhoi * rhoi)

    return launcher(dfsph_velocity_main)
