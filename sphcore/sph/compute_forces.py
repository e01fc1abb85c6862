"""Acceleration from pressure (Monaghan 1992: pressure.py), viscosity (laminar, Mueller et al. 2003, or artificial,
Monaghan 1992: viscosity.py; wall images' velocities: walls.py), surface tension by cohesion (Becker &
Teschner 2007: cohesion.py) and gravity, one invocation per particle; with shifting (shifting.py) also the sums
integrate shifts the particle by; for the bodies' wall particles (BODIES) the fluid's force on them. Each pair's
terms are `pair`'s, called by
the one neighbour walk (walk.py: the list or the scan; wall and obstacle images as in compute_density). Each
optional term is compiled out by its closure constant, as the shader's by its specialization constant.

Mirror of shaders/sph/compute_forces.comp: same names, same statement order, same step
labels. A GLSL vec3 local `v` is `v_x, v_y, v_z` here. The shader's private globals are `own` (i's state and
the buffers `pair` reads) and `state` (the sums) here, tuples handed through the walk (walk.py).
"""
from functools import lru_cache

import numpy as np
from numba import njit

from sphcore.sph.band_rows import band_row, band_row_at
from sphcore.sph.cohesion import cohesion
from sphcore.sph.dfsph import CONTROL_REBUILD
from sphcore.sph.kernels import kernels
from sphcore.sph.pairs import pairs
from sphcore.sph.pressure import pressure
from sphcore.sph.shifting import shifting
from sphcore.sph.viscosity import viscosity
from sphcore.sph.walk import walk
from sphcore.sph.walls import walls
from sphcore.workgroups import launcher


@lru_cache(maxsize=None)
def compute_forces(spec, real=np.float32):
    VISCOSITY, SURFACE_TENSION, GRAVITY = spec.VISCOSITY, spec.SURFACE_TENSION, spec.GRAVITY
    DFSPH, SHIFTING, BODIES, NO_SLIP, LIST_SKIN = spec.DFSPH, spec.SHIFTING, spec.BODIES, spec.NO_SLIP, spec.LIST_SKIN
    image_velocity = walls(spec, real).image_velocity
    viscous_term = viscosity(spec, real).viscous_term
    viscous_acceleration = viscosity(spec, real).viscous_acceleration
    pair_gradient = kernels(spec, real).pair_gradient
    kernel_laplacian = kernels(spec, real).kernel_laplacian
    pressure_monaghan = pressure(real)
    pair_direction = pairs(real)
    cohesion_becker = cohesion(spec, real)
    shifting_lind = shifting(spec, real).shifting_lind

    @njit(inline="always")  # (numba inlines it into its caller: no tuple crosses a call)
    def pair(own, state, i, j, image, r_x, r_y, r_z, r2, inward_x, inward_y, inward_z):
        """One pair's terms (walk.py hands over every other particle and image within h of i): pressure
        (pressure.py: Monaghan 1992's symmetric form; DFSPH: the solver's), viscosity of the scene's model
        (viscosity.py; an image's velocity is the wall model's, walls.py) and cohesion between real particles
        only (cohesion.py: Becker & Teschner 2007; the walls are not wetted); the shifting sums, images included
        (shifting.py: Lind et al. 2012). A wall particle and the fluid: the pressure term, the viscous one with
        NO_SLIP only (its velocity wall_pressure's), the shifting sums; two wall particles: nothing."""
        P, particle_v, particle_rho, particle_p, particle_id, wall_i, vi_x, vi_y, vi_z, rhoi, pi_rho2 = own
        (f_pressure_x, f_pressure_y, f_pressure_z, f_viscosity_x, f_viscosity_y, f_viscosity_z,
         f_cohesion_x, f_cohesion_y, f_cohesion_z, f_shift_x, f_shift_y, f_shift_z, f_shift_w) = state
        wall_j = BODIES and particle_id[j] >= P.fluid_count
        if wall_i and wall_j:
            return state
        rhoj = particle_rho[j]
        pj = particle_p[j]
        rlen = np.sqrt(r2)
        grad = pair_gradient(P, r2, rlen, image)  # kernels.glsl: m grad_i W_ij = -P.pressure_coef grad r_hat
        # the direction from the neighbour to i (pairs.glsl; where the two coincide: an image along its plane's
        # inward normal, two particles along x, antisymmetrically in (i, j))
        r_hat_x, r_hat_y, r_hat_z = pair_direction(r_x, r_y, r_z, rlen, i, j, image, inward_x, inward_y, inward_z)
        if not DFSPH:
            fp = pressure_monaghan(P, pi_rho2, pj, rhoj, grad)
            f_pressure_x += fp * r_hat_x
            f_pressure_y += fp * r_hat_y
            f_pressure_z += fp * r_hat_z
        if VISCOSITY and (NO_SLIP or not (wall_i or wall_j)):
            vk_x, vk_y, vk_z = image_velocity(particle_v[j, 0], particle_v[j, 1], particle_v[j, 2], image)
            t_x, t_y, t_z = viscous_term(P, vi_x, vi_y, vi_z, vk_x, vk_y, vk_z, r_x, r_y, r_z, r2, rhoi, rhoj, grad,
                                         kernel_laplacian(P, r2, rlen), r_hat_x, r_hat_y, r_hat_z)
            f_viscosity_x += t_x
            f_viscosity_y += t_y
            f_viscosity_z += t_z
        if SURFACE_TENSION and image == 0 and not wall_j:
            t_x, t_y, t_z = cohesion_becker(P, r2, r_x, r_y, r_z)
            f_cohesion_x += t_x
            f_cohesion_y += t_y
            f_cohesion_z += t_z
        if SHIFTING > 0:
            t_x, t_y, t_z, t_w = shifting_lind(P, r2, rlen, rhoj, grad, r_hat_x, r_hat_y, r_hat_z)
            f_shift_x += t_x
            f_shift_y += t_y
            f_shift_z += t_z
            f_shift_w += t_w
        return (f_pressure_x, f_pressure_y, f_pressure_z, f_viscosity_x, f_viscosity_y, f_viscosity_z,
                f_cohesion_x, f_cohesion_y, f_cohesion_z, f_shift_x, f_shift_y, f_shift_z, f_shift_w)

    walk_neighbours = walk(spec, real, pair)

    @njit
    def compute_forces_main(i, params, particle_x, particle_v, particle_a, particle_rho, particle_p, particle_id,
                            cell_pyramid, cell_start, scratch_x, obstacle_box, control, neighbours,
                            neighbour_count, particle_shift, band_rows):
        P = params[0]
        # [1] one invocation per particle; the grid is rounded up to whole work groups. On a rank of sphcore.parallel
        #     (P.owned_end > 0) the rows the sort gave its slab's cells alone: nothing reads a halo row's
        #     acceleration (the next exchange writes over the row). A rank whose exchange overlaps the step's end
        #     runs two passes: D.level 1 one invocation per row its pick reads (band_rows.py: an indirect dispatch of
        #     as many), which it sends before the second, D.level 2 the others; else (0) one takes every row
        if P.level == 1:
            found, i, e = band_row_at(i, band_rows)
            if not found:
                return
        if i >= P.n:
            return
        if P.owned_end > 0 and (i < cell_start[P.owned_first] or (P.owned_end < P.cell_total
                                                                  and i >= cell_start[P.owned_end])):
            if LIST_SKIN > 0 and i == 0:
                control[CONTROL_REBUILD] = 0
            return
        if P.level == 2 and band_row(i, band_rows):
            return
        # [2] own state (BODIES: whether i is a wall particle)
        wall_i = BODIES and particle_id[i] >= P.fluid_count
        xi_x = particle_x[i, 0]
        xi_y = particle_x[i, 1]
        xi_z = particle_x[i, 2]
        vi_x = particle_v[i, 0]
        vi_y = particle_v[i, 1]
        vi_z = particle_v[i, 2]
        rhoi = particle_rho[i]
        pi = particle_p[i]
        pi_rho2 = pi / (rhoi * rhoi)
        # [3] sums over every other particle and every wall or obstacle image within h (walk.glsl: i's list, or the
        #     scan)
        zero = real(0.0)
        (f_pressure_x, f_pressure_y, f_pressure_z, f_viscosity_x, f_viscosity_y, f_viscosity_z,
         f_cohesion_x, f_cohesion_y, f_cohesion_z, f_shift_x, f_shift_y, f_shift_z, f_shift_w) = walk_neighbours(
            P, particle_x, scratch_x, cell_pyramid, cell_start, obstacle_box, neighbours, neighbour_count, i, xi_x, xi_y,
            xi_z, (P, particle_v, particle_rho, particle_p, particle_id, wall_i, vi_x, vi_y, vi_z, rhoi, pi_rho2),
            (zero, zero, zero, zero, zero, zero, zero, zero, zero, zero, zero, zero, zero))
        # [4] a_i = f_pressure + viscous acceleration + cohesion + g (f_pressure is per unit mass; the
        #     laminar sum is divided by rho_i, viscosity.glsl); a wall particle: the fluid's terms only
        a_x = f_pressure_x
        a_y = f_pressure_y
        a_z = f_pressure_z
        if VISCOSITY:
            t_x, t_y, t_z = viscous_acceleration(f_viscosity_x, f_viscosity_y, f_viscosity_z, rhoi)
            a_x += t_x
            a_y += t_y
            a_z += t_z
        if SURFACE_TENSION and not wall_i:
            a_x += P.cohesion_coef * f_cohesion_x
            a_y += P.cohesion_coef * f_cohesion_y
            a_z += P.cohesion_coef * f_cohesion_z
        if GRAVITY and not wall_i:
            a_x += P.gravity[0]
            a_y += P.gravity[1]
            a_z += P.gravity[2]
        # [5] store, with shifting its sums (grad C_i, div r_i) for integrate; reused lists: the next build is
        #     integrate's to ask for (every dispatch that reads the request has run: backends.plan)
        particle_a[i, 0] = a_x
        particle_a[i, 1] = a_y
        particle_a[i, 2] = a_z
        particle_a[i, 3] = real(0.0)
        if SHIFTING > 0:
            particle_shift[i, 0] = f_shift_x
            particle_shift[i, 1] = f_shift_y
            particle_shift[i, 2] = f_shift_z
            particle_shift[i, 3] = f_shift_w
        if LIST_SKIN > 0 and i == 0:
            control[CONTROL_REBUILD] = 0

    return launcher(compute_forces_main)
