"""DFSPH's factor alpha_i (Bender & Koschier 2017, eq. 11) times omega = fluid.relaxation, one invocation per
particle, after compute_density; invocation 0 also starts the step's two solves (dfsph.py: their flags, counts and
indirect dispatches), and every particle's pressure starts from 0. The sums walk the particle's neighbour
list (walk.py: walk_list), which compute_density's scan wrote and every sweep of the solves walks too (dfsph.py). The sum of each
particle's V grad W_ij goes to particle_gradient_sum (dfsph_residual).

Mirror of shaders/sph/dfsph_factor.comp: same names, same statement order, same step labels.
A GLSL vec3 local `v` is `v_x, v_y, v_z` here.
"""
from functools import lru_cache

import numpy as np
from numba import njit, prange

from sphcore.numba_cache import cached
from sphcore.sph.cells import cells
from sphcore.sph.dfsph import (CONTROL_DONE, CONTROL_ITERATIONS, CONTROL_OVERFLOW_STEP, CONTROL_STEP,
                               SOLVE_DENSITY, SOLVE_DIVERGENCE, STATE_RELAXATION, WARM_START, dispatch_base,
                               list_slots)
from sphcore.sph.kernels import kernels
from sphcore.sph.neighbour_list import neighbour_list
from sphcore.sph.obstacles import obstacles
from sphcore.sph.walk import list_walk


@lru_cache(maxsize=None)
def dfsph_factor(spec, real=np.float32):
    near_walls = cells(spec, real).near_walls
    near_obstacles = obstacles(spec, real).near_obstacles
    MAX_NEIGHBOURS, GRADIENTS = spec.MAX_NEIGHBOURS, spec.GRADIENTS
    list_slot = list_slots(spec)
    pair_gradient = kernels(spec, real).pair_gradient
    listed_pair = neighbour_list(spec, real).listed_pair

    @njit(inline="always")  # (numba inlines it into its caller: no tuple crosses a call)
    def list_entry(own, state, i, slot, chunk):
        """One entry of i's list (walk.py: walk_list hands over each slot): the neighbour j, or its image, and the
        direction from it to i (neighbour_list.py); g = V grad_i W_ij into the sums, and with GRADIENTS stored at
        the entry's slot. Returns (chunk, the sums)."""
        P, particle_x, neighbours, neighbour_gradients, xi_x, xi_y, xi_z, wall_x, wall_y, wall_z, inward_x, inward_y, \
            inward_z, coef = own
        sum_grad_x, sum_grad_y, sum_grad_z, sum_grad2 = state
        chunk, j, image, r_x, r_y, r_z, r2, rlen, r_hat_x, r_hat_y, r_hat_z = listed_pair(
            P, particle_x, neighbours, i, slot, chunk, xi_x, xi_y, xi_z, wall_x, wall_y, wall_z, inward_x,
            inward_y, inward_z)
        g = coef * pair_gradient(P, r2, rlen, image)
        grad_x = g * r_hat_x
        grad_y = g * r_hat_y
        grad_z = g * r_hat_z
        sum_grad_x -= grad_x
        sum_grad_y -= grad_y
        sum_grad_z -= grad_z
        sum_grad2 += g * g
        if GRADIENTS:
            k = list_slot(P, i, slot)
            neighbour_gradients[k, 0] = -grad_x
            neighbour_gradients[k, 1] = -grad_y
            neighbour_gradients[k, 2] = -grad_z
            neighbour_gradients[k, 3] = real(0.0)
        return chunk, (sum_grad_x, sum_grad_y, sum_grad_z, sum_grad2)

    walk_list = list_walk(list_entry)

    @njit
    def dfsph_factor_main(i, local_size, params, particle_x, particle_p, obstacle_box,
                          particle_alpha, control, dfsph_state, particle_kappa, neighbours,
                          neighbour_count, neighbour_gradients, particle_gradient_sum):
        P = params[0]
        # [1] one invocation per particle; invocation 0 also starts the step's solves
        if i >= P.n:
            return
        if i == 0:
            control[CONTROL_DONE + SOLVE_DIVERGENCE] = 0
            control[CONTROL_DONE + SOLVE_DENSITY] = 0
            control[CONTROL_ITERATIONS + SOLVE_DIVERGENCE] = 0
            control[CONTROL_ITERATIONS + SOLVE_DENSITY] = 0
            for solve in range(SOLVE_DIVERGENCE, SOLVE_DENSITY + 1):
                base = dispatch_base(solve)
                control[base] = (P.n + local_size - 1) // local_size
                control[base + 1] = 1
                control[base + 2] = 1
        # [2] own position; wall and obstacle images as in compute_density
        xi_x = particle_x[i, 0]
        xi_y = particle_x[i, 1]
        xi_z = particle_x[i, 2]
        mirrored, wall_x, wall_y, wall_z = near_walls(P, xi_x, xi_y, xi_z)
        mirrored, wall_x, wall_y, wall_z, inward_x, inward_y, inward_z = near_obstacles(
            P, obstacle_box, xi_x, xi_y, xi_z, mirrored, wall_x, wall_y, wall_z)
        # [3] sums over the particle's list (compute_density wrote it this step, in its scan's order: every
        #     other particle and every image within h) of g = V grad_i W_ij = -coef kernel_gradient r_hat
        #     (coef = pressure_coef / rho_0): their sum, and the sum of |g|^2; with GRADIENTS each g stored for
        #     the solves' sweeps (the positions do not move before integrate); walk.py: walk_list, list_entry above
        coef = real(P.pressure_coef) / real(P.rest_density)
        zero = real(0.0)
        count = int(neighbour_count[i])
        sum_grad_x, sum_grad_y, sum_grad_z, sum_grad2 = walk_list(
            i, min(count, MAX_NEIGHBOURS), (P, particle_x, neighbours, neighbour_gradients, xi_x, xi_y, xi_z, wall_x,
                                            wall_y, wall_z, inward_x, inward_y, inward_z, coef), (zero, zero, zero, zero))
        # [4] alpha_i, relaxed; 0 for a particle (nearly) alone, whose residual is 0 anyway
        s = sum_grad_x * sum_grad_x + sum_grad_y * sum_grad_y + sum_grad_z * sum_grad_z + sum_grad2
        alpha = real(0.0)
        if s > real(1e-6) / real(P.h2):
            alpha = real(1.0) / s
        alpha *= real(dfsph_state[STATE_RELAXATION])
        # [5] store; the pressure starts from 0 and the stiffness sum from WARM_START times the last step's
        #     (dfsph_velocity accumulates both)
        particle_alpha[i] = alpha
        particle_gradient_sum[i, 0] = sum_grad_x
        particle_gradient_sum[i, 1] = sum_grad_y
        particle_gradient_sum[i, 2] = sum_grad_z
        particle_gradient_sum[i, 3] = real(0.0)
        particle_p[i] = real(0.0)
        particle_kappa[i] = real(WARM_START) * particle_kappa[i]
        # [6] a list too long for its MAX_NEIGHBOURS slots marks the step (the same value from every
        #     invocation that writes it), and the host stops the run
        if count > MAX_NEIGHBOURS and control[CONTROL_OVERFLOW_STEP] == 0:
            control[CONTROL_OVERFLOW_STEP] = control[CONTROL_STEP] + 1

    @njit(parallel=True, error_model="numpy")
    def launch(n_groups, local_size, params, particle_x, particle_p, obstacle_box,
               particle_alpha, control, dfsph_state, particle_kappa, neighbours, neighbour_count,
               neighbour_gradients, particle_gradient_sum):
        for group in prange(n_groups):
            for lid in range(local_size):
                dfsph_factor_main(group * local_size + lid, local_size, params, particle_x, particle_p, obstacle_box,
                                  particle_alpha, control, dfsph_state, particle_kappa, neighbours,
                                  neighbour_count, neighbour_gradients, particle_gradient_sum)

    return cached(launch)
