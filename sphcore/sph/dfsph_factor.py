"""DFSPH's factor alpha_i (Bender & Koschier 2017, eq. 11), one invocation per particle, after
compute_density; invocation 0 also starts the step's two solves (dfsph.py: their flags, counts and
indirect dispatches), and every particle's pressure starts from 0. The scan also writes the particle's
neighbour list, which every sweep of the solves walks (dfsph.py).

Mirror of shaders/sph/dfsph_factor.comp: same names, same statement order, same step labels.
A GLSL vec3 local `v` is `v_x, v_y, v_z` here.
"""
from functools import lru_cache

import numpy as np
from numba import njit, prange

from sphcore.numba_cache import cached
from sphcore.sph.cells import cells
from sphcore.sph.dfsph import (CONTROL_DONE, CONTROL_ITERATIONS, CONTROL_OVERFLOW_STEP, CONTROL_STEP,
                               IMAGE_SHIFT, SOLVE_DENSITY, SOLVE_DIVERGENCE, WARM_START, dispatch_base)
from sphcore.sph.kernels import kernels
from sphcore.sph.obstacles import obstacles
from sphcore.sph.pairs import pairs


@lru_cache(maxsize=None)
def dfsph_factor(spec, real=np.float32):
    GRID = spec.GRID
    cell_of, cell_index, near_walls, reflected, range_count, range_cells = cells(spec, real)
    near_obstacles, solid = obstacles(spec, real)
    OBSTACLES = spec.OBSTACLES
    MAX_NEIGHBOURS = spec.MAX_NEIGHBOURS
    kernel_w, kernel_gradient, pair_gradient, kernel_laplacian = kernels(spec, real)
    pair_direction = pairs(real)

    @njit
    def dfsph_factor_main(i, local_size, params, particle_x, particle_p, cell_pyramid, cell_start, obstacle_box,
                          particle_alpha, dfsph_control, particle_kappa, dfsph_neighbours, dfsph_neighbour_count):
        P = params[0]
        # [1] one invocation per particle; invocation 0 also starts the step's solves
        if i >= P.n:
            return
        if i == 0:
            dfsph_control[CONTROL_DONE + SOLVE_DIVERGENCE] = 0
            dfsph_control[CONTROL_DONE + SOLVE_DENSITY] = 0
            dfsph_control[CONTROL_ITERATIONS + SOLVE_DIVERGENCE] = 0
            dfsph_control[CONTROL_ITERATIONS + SOLVE_DENSITY] = 0
            for solve in range(SOLVE_DIVERGENCE, SOLVE_DENSITY + 1):
                base = dispatch_base(solve)
                dfsph_control[base] = (P.n + local_size - 1) // local_size
                dfsph_control[base + 1] = 1
                dfsph_control[base + 2] = 1
        # [2] own position; wall and obstacle images as in compute_density
        xi_x = particle_x[i, 0]
        xi_y = particle_x[i, 1]
        xi_z = particle_x[i, 2]
        mirrored, wall_x, wall_y, wall_z = near_walls(P, xi_x, xi_y, xi_z)
        mirrored, wall_x, wall_y, wall_z, inward_x, inward_y, inward_z = near_obstacles(
            P, obstacle_box, xi_x, xi_y, xi_z, mirrored, wall_x, wall_y, wall_z)
        # [3] sums over every other particle and every image within h of g = V grad_i W_ij = -coef
        #     kernel_gradient r_hat (coef = pressure_coef / rho_0): their sum, and the sum of |g|^2; each
        #     of them into the list, in the scan's order (dfsph.py)
        coef = real(P.pressure_coef) / real(P.rest_density)
        sum_grad_x = real(0.0)
        sum_grad_y = real(0.0)
        sum_grad_z = real(0.0)
        sum_grad2 = real(0.0)
        count = 0
        for image in range(8):
            if (image & ~mirrored) != 0:
                continue
            xm_x, xm_y, xm_z = reflected(xi_x, xi_y, xi_z, wall_x, wall_y, wall_z, image)
            base_x, base_y, base_z = cell_of(P, xm_x, xm_y, xm_z)
            # [4] the 3^dim cells around xm, as ranges of sorted particles (cells.glsl: range_cells)
            for k in range(range_count()):
                start = 0
                end = int(P.n)
                if GRID:
                    inside, first, last = range_cells(P, base_x, base_y, base_z, k)
                    if not inside:
                        continue
                    start = int(cell_start[first])
                    end = int(cell_start[last]) + int(cell_pyramid[last])
                for j in range(start, end):
                    if j == i and image == 0:
                        continue
                    xk, yk, zk = particle_x[j, 0], particle_x[j, 1], particle_x[j, 2]
                    if image != 0:
                        xk, yk, zk = reflected(xk, yk, zk, wall_x, wall_y, wall_z, image)
                    if OBSTACLES > 0 and image != 0 and not solid(P, obstacle_box, xk, yk, zk):
                        continue  # (obstacles.glsl)
                    r_x = xi_x - xk
                    r_y = xi_y - yk
                    r_z = xi_z - zk
                    r2 = r_x * r_x + r_y * r_y + r_z * r_z
                    if r2 >= P.h2:
                        continue
                    rlen = np.sqrt(r2)
                    # [5] direction from the neighbour to i (pairs.glsl)
                    r_hat_x, r_hat_y, r_hat_z = pair_direction(r_x, r_y, r_z, rlen, i, j, image, inward_x,
                                                                      inward_y, inward_z)
                    g = coef * pair_gradient(P, r2, rlen, image)
                    sum_grad_x -= g * r_hat_x
                    sum_grad_y -= g * r_hat_y
                    sum_grad_z -= g * r_hat_z
                    sum_grad2 += g * g
                    if count < MAX_NEIGHBOURS:
                        dfsph_neighbours[count * P.n + i] = j | (image << IMAGE_SHIFT)
                    count += 1
        # [6] alpha_i; 0 for a particle (nearly) alone, whose residual is 0 anyway
        s = sum_grad_x * sum_grad_x + sum_grad_y * sum_grad_y + sum_grad_z * sum_grad_z + sum_grad2
        alpha = real(0.0)
        if s > real(1e-6) / real(P.h2):
            alpha = real(1.0) / s
        # [7] store; the pressure starts from 0 and the stiffness sum from WARM_START times the last step's
        #     (dfsph_velocity accumulates both)
        particle_alpha[i] = alpha
        particle_p[i] = real(0.0)
        particle_kappa[i] = real(WARM_START) * particle_kappa[i]
        # [8] the list's length; one too long for its MAX_NEIGHBOURS slots marks the step (the same value from
        #     every invocation that writes it), and the host stops the run
        dfsph_neighbour_count[i] = count
        if count > MAX_NEIGHBOURS and dfsph_control[CONTROL_OVERFLOW_STEP] == 0:
            dfsph_control[CONTROL_OVERFLOW_STEP] = dfsph_control[CONTROL_STEP] + 1

    @njit(parallel=True, error_model="numpy")
    def launch(n_groups, local_size, params, particle_x, particle_p, cell_pyramid, cell_start, obstacle_box,
               particle_alpha, dfsph_control, particle_kappa, dfsph_neighbours, dfsph_neighbour_count):
        for group in prange(n_groups):
            for lid in range(local_size):
                dfsph_factor_main(group * local_size + lid, local_size, params, particle_x, particle_p, cell_pyramid,
                                  cell_start, obstacle_box, particle_alpha, dfsph_control, particle_kappa,
                                  dfsph_neighbours, dfsph_neighbour_count)

    return cached(launch)
