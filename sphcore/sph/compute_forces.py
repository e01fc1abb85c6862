"""Acceleration from pressure (spiky gradient), viscosity (laminar, Mueller et al. 2003, or artificial,
Monaghan 1992: viscosity.py; wall images' velocities: walls.py), surface
tension by cohesion (Becker & Teschner 2007) and gravity, one invocation per particle.
Neighbours, wall and obstacle images as in compute_density; with neighbour lists (DFSPH, and the state
equation where they fit: Scene.spec_for), the step's list (compute_density: the same pairs, in the same order,
so the same bits). Each optional term is compiled out by its closure constant, as the shader's by its
specialization constant.

Mirror of shaders/sph/compute_forces.comp: same names, same statement order, same step
labels. A GLSL vec3 local `v` is `v_x, v_y, v_z` here.
"""
from functools import lru_cache

import numpy as np
from numba import njit

from sphcore.sph.cells import cells, skin
from sphcore.sph.dfsph import CONTROL_REBUILD
from sphcore.sph.kernels import kernels
from sphcore.sph.neighbour_list import neighbour_list
from sphcore.sph.obstacles import obstacles
from sphcore.sph.pairs import pairs
from sphcore.sph.viscosity import viscosity
from sphcore.sph.walls import walls
from sphcore.workgroups import launcher



@lru_cache(maxsize=None)
def compute_forces(spec, real=np.float32):
    GRID = spec.GRID
    VISCOSITY, SURFACE_TENSION, GRAVITY = spec.VISCOSITY, spec.SURFACE_TENSION, spec.GRAVITY
    DFSPH, MAX_NEIGHBOURS = spec.DFSPH, spec.MAX_NEIGHBOURS
    cell_of, cell_index, near_walls, reflected, range_count, range_cells = cells(spec, real)
    near_walls_within, list_reach = skin(spec, real)[:2]
    LIST_SKIN = spec.LIST_SKIN
    near_obstacles, solid = obstacles(spec, real)
    OBSTACLES = spec.OBSTACLES
    image_velocity = walls(spec, real)[2]
    viscous_term, viscous_acceleration = viscosity(spec, real)[2:]
    kernel_w, kernel_gradient, pair_gradient, kernel_laplacian = kernels(spec, real)
    pair_direction = pairs(real)
    listed_pair = neighbour_list(spec, real)[0]

    @njit
    def compute_forces_main(i, params, particle_x, particle_v, particle_a, particle_rho, particle_p,
                            cell_pyramid, cell_start, scratch_x, obstacle_box, control, neighbours,
                            neighbour_count):
        P = params[0]
        # [1] one invocation per particle; the grid is rounded up to whole work groups
        if i >= P.n:
            return
        # [2] own state
        xi_x = particle_x[i, 0]
        xi_y = particle_x[i, 1]
        xi_z = particle_x[i, 2]
        vi_x = particle_v[i, 0]
        vi_y = particle_v[i, 1]
        vi_z = particle_v[i, 2]
        rhoi = particle_rho[i]
        pi = particle_p[i]
        pi_rho2 = pi / (rhoi * rhoi)
        # [3] wall and obstacle images, as in compute_density; an image's normal velocity is reversed
        #     (free slip); `inward` points from each axis's mirror plane into the fluid. Reused lists (LIST_SKIN):
        #     the walls and cells of where i was at the list's build, as compute_density's
        x_built_x = scratch_x[i, 0] if LIST_SKIN > 0 else xi_x
        x_built_y = scratch_x[i, 1] if LIST_SKIN > 0 else xi_y
        x_built_z = scratch_x[i, 2] if LIST_SKIN > 0 else xi_z
        if LIST_SKIN > 0:
            mirrored, wall_x, wall_y, wall_z = near_walls_within(P, x_built_x, x_built_y, x_built_z, list_reach(P))
        else:
            mirrored, wall_x, wall_y, wall_z = near_walls(P, xi_x, xi_y, xi_z)
        mirrored, wall_x, wall_y, wall_z, inward_x, inward_y, inward_z = near_obstacles(
            P, obstacle_box, xi_x, xi_y, xi_z, mirrored, wall_x, wall_y, wall_z)
        # [4] sums over every other particle and every image within h
        f_pressure_x = real(0.0)
        f_pressure_y = real(0.0)
        f_pressure_z = real(0.0)
        f_viscosity_x = real(0.0)
        f_viscosity_y = real(0.0)
        f_viscosity_z = real(0.0)
        f_cohesion_x = real(0.0)
        f_cohesion_y = real(0.0)
        f_cohesion_z = real(0.0)
        # [5] with neighbour lists (Scene.spec_for), the list compute_density wrote from these
        #     positions this step (neighbour_list.glsl): the pairs of the scan below in its order, with the same
        #     terms as [8]-[10]. A particle with more neighbours than its list's slots is scanned instead
        listed = MAX_NEIGHBOURS > 0 and int(neighbour_count[i]) <= MAX_NEIGHBOURS
        if listed:
            count = int(neighbour_count[i])
            chunk = (0, 0, 0, 0)
            for slot in range(count):
                chunk, j, image, r_x, r_y, r_z, r2, rlen, r_hat_x, r_hat_y, r_hat_z = listed_pair(
                    P, particle_x, neighbours, i, slot, chunk, xi_x, xi_y, xi_z, wall_x, wall_y, wall_z,
                    inward_x, inward_y, inward_z)
                if LIST_SKIN > 0 and r2 >= P.h2:
                    continue  # (a reused list holds pairs out to list_reach)
                grad = pair_gradient(P, r2, rlen, image)
                rhoj = particle_rho[j]
                if not DFSPH:
                    fp = P.pressure_coef * (pi_rho2 + particle_p[j] / (rhoj * rhoj)) * grad
                    f_pressure_x += fp * r_hat_x
                    f_pressure_y += fp * r_hat_y
                    f_pressure_z += fp * r_hat_z
                if VISCOSITY:
                    vk_x, vk_y, vk_z = image_velocity(particle_v[j, 0], particle_v[j, 1], particle_v[j, 2], image)
                    t_x, t_y, t_z = viscous_term(P, vi_x, vi_y, vi_z, vk_x, vk_y, vk_z, r_x, r_y, r_z, r2, rhoi,
                                                 rhoj, grad, kernel_laplacian(P, r2, rlen), r_hat_x, r_hat_y,
                                                 r_hat_z)
                    f_viscosity_x += t_x
                    f_viscosity_y += t_y
                    f_viscosity_z += t_z
                if SURFACE_TENSION and image == 0:
                    w = kernel_w(P, r2)
                    f_cohesion_x += w * r_x
                    f_cohesion_y += w * r_y
                    f_cohesion_z += w * r_z
        for image in range(8):
            if listed or (image & ~mirrored) != 0:
                continue
            xm_x, xm_y, xm_z = reflected(x_built_x, x_built_y, x_built_z, wall_x, wall_y, wall_z, image)
            base_x, base_y, base_z = cell_of(P, xm_x, xm_y, xm_z)
            # [6] the 3^dim cells around xm, as ranges of sorted particles (cells.glsl: range_cells)
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
                    rhoj = particle_rho[j]
                    pj = particle_p[j]
                    rlen = np.sqrt(r2)
                    grad = pair_gradient(P, r2, rlen, image)  # kernels.glsl: m grad_i W_ij = -P.pressure_coef grad r_hat
                    # [7] direction from the neighbour to i. Where the two coincide (normalize(0) is
                    #     NaN): an image coincides with i only on a wall or an obstacle's face, so push
                    #     along its inward normal; two particles are pushed apart along x,
                    #     antisymmetrically in (i, j), so momentum is conserved
                    r_hat_x, r_hat_y, r_hat_z = pair_direction(r_x, r_y, r_z, rlen, i, j, image, inward_x,
                                                                      inward_y, inward_z)
                    # [8] pressure: -sum_j m (p_i / rho_i^2 + p_j / rho_j^2) grad W (kernels.glsl), the form that
                    #     conserves momentum and energy with summation or continuity density (Monaghan 1992).
                    #     Mueller et al. (2003) and seed 1 use m (p_i + p_j) / (2 rho_j): that estimates
                    #     grad p / 2, so a column at rest settles at twice its hydrostatic pressure
                    fp = P.pressure_coef * (pi_rho2 + pj / (rhoj * rhoj)) * grad
                    if not DFSPH:  # DFSPH: the pressure is the solver's (dfsph.glsl)
                        f_pressure_x += fp * r_hat_x
                        f_pressure_y += fp * r_hat_y
                        f_pressure_z += fp * r_hat_z
                    # [9] viscosity of the scene's model (viscosity.glsl: laminar, Mueller et al. 2003, or
                    #     artificial, Monaghan 1992); an image's velocity is the wall model's (walls.glsl:
                    #     free slip reverses its normal component, no slip all of it)
                    if VISCOSITY:
                        vk_x, vk_y, vk_z = image_velocity(particle_v[j, 0], particle_v[j, 1], particle_v[j, 2], image)
                        t_x, t_y, t_z = viscous_term(P, vi_x, vi_y, vi_z, vk_x, vk_y, vk_z, r_x, r_y, r_z, r2, rhoi,
                                                     rhoj, grad, kernel_laplacian(P, r2, rlen), r_hat_x, r_hat_y, r_hat_z)
                        f_viscosity_x += t_x
                        f_viscosity_y += t_y
                        f_viscosity_z += t_z
                    # [10] cohesion: -kappa sum_j W(r_ij) (x_i - x_j) (equal masses), between real
                    #     particles only: the walls are not wetted
                    if SURFACE_TENSION and image == 0:
                        w = kernel_w(P, r2)
                        f_cohesion_x += w * r_x
                        f_cohesion_y += w * r_y
                        f_cohesion_z += w * r_z
        # [11] a_i = f_pressure + viscous acceleration + cohesion + g (f_pressure is per unit mass; the
        #      laminar sum is divided by rho_i, viscosity.glsl)
        a_x = f_pressure_x
        a_y = f_pressure_y
        a_z = f_pressure_z
        if VISCOSITY:
            t_x, t_y, t_z = viscous_acceleration(f_viscosity_x, f_viscosity_y, f_viscosity_z, rhoi)
            a_x += t_x
            a_y += t_y
            a_z += t_z
        if SURFACE_TENSION:
            a_x += P.cohesion_coef * f_cohesion_x
            a_y += P.cohesion_coef * f_cohesion_y
            a_z += P.cohesion_coef * f_cohesion_z
        if GRAVITY:
            a_x += P.gravity[0]
            a_y += P.gravity[1]
            a_z += P.gravity[2]
        # [12] store; reused lists: the next build is integrate's to ask for (every dispatch that reads the request
        #      has run: backends.plan)
        particle_a[i, 0] = a_x
        particle_a[i, 1] = a_y
        particle_a[i, 2] = a_z
        particle_a[i, 3] = real(0.0)
        if LIST_SKIN > 0 and i == 0:
            control[CONTROL_REBUILD] = 0

    return launcher(compute_forces_main)
