"""The bodies' wall particles: their pressure, density and (no slip) velocity extrapolated from the fluid
(Adami, Hu & Adams 2012), one invocation per particle, between the density and the forces.

Mirror of shaders/sph/wall_pressure.comp: same names, same statement order, same step labels (the formulas
and their equation numbers are there). The shader's private sums are the tuple `state` here (walk.py).
"""
from functools import lru_cache

import numpy as np
from numba import njit

from sphcore.sph.kernels import kernels
from sphcore.sph.walk import walk
from sphcore.sph.walls import walls
from sphcore.workgroups import launcher


@lru_cache(maxsize=None)
def wall_pressure(spec, real=np.float32):
    NO_SLIP, TAIT, GRAVITY, CONTINUITY = spec.NO_SLIP, spec.TAIT, spec.GRAVITY, spec.CONTINUITY
    image_velocity = walls(spec, real).image_velocity
    kernel_w = kernels(spec, real).kernel_w

    @njit(inline="always")
    def pair(own, state, i, j, image, r_x, r_y, r_z, r2, inward_x, inward_y, inward_z):
        """One pair (walk.py): a fluid particle j, or its image, at r = x_w - x_k; other wall particles are
        skipped."""
        P, particle_v, particle_rho, particle_p, particle_id = own
        sum_w, sum_p, sum_rho_r_x, sum_rho_r_y, sum_rho_r_z, sum_v_x, sum_v_y, sum_v_z = state
        if particle_id[j] >= P.fluid_count:
            return state
        w = kernel_w(P, r2)
        sum_w += w
        sum_p += particle_p[j] * w
        rho_w = particle_rho[j] * w
        sum_rho_r_x += rho_w * r_x
        sum_rho_r_y += rho_w * r_y
        sum_rho_r_z += rho_w * r_z
        if NO_SLIP:
            vk_x, vk_y, vk_z = image_velocity(particle_v[j, 0], particle_v[j, 1], particle_v[j, 2], image)
            sum_v_x += vk_x * w
            sum_v_y += vk_y * w
            sum_v_z += vk_z * w
        return sum_w, sum_p, sum_rho_r_x, sum_rho_r_y, sum_rho_r_z, sum_v_x, sum_v_y, sum_v_z

    walk_neighbours = walk(spec, real, pair)

    @njit
    def wall_density(P, p):
        """The density of pressure p: the equation of state's inverse (see the shader)."""
        if not TAIT:
            return P.rest_density + p / P.stiffness
        y = max(real(1.0) + p / P.stiffness, real(0.5))
        x = real(1.0) + (y - real(1.0)) / real(7.0)
        for _ in range(4):
            x2 = x * x
            x6 = x2 * x2 * x2
            x -= (x6 * x - y) / (real(7.0) * x6)
        return P.rest_density * x

    @njit
    def wall_pressure_main(i, params, particle_x, particle_v, particle_rho, particle_p, particle_id, cell_pyramid,
                           cell_start, scratch_x, obstacle_box, neighbours, neighbour_count):
        P = params[0]
        # [1] one invocation per wall particle; the grid is rounded up to whole work groups
        if i >= P.n or particle_id[i] < P.fluid_count:
            return
        # [2] the sums over the fluid and its images within h (walk.glsl)
        xi_x = particle_x[i, 0]
        xi_y = particle_x[i, 1]
        xi_z = particle_x[i, 2]
        zero = real(0.0)
        sum_w, sum_p, sum_rho_r_x, sum_rho_r_y, sum_rho_r_z, sum_v_x, sum_v_y, sum_v_z = walk_neighbours(
            P, particle_x, scratch_x, cell_pyramid, cell_start, obstacle_box, neighbours, neighbour_count, i, xi_x,
            xi_y, xi_z, (P, particle_v, particle_rho, particle_p, particle_id), (zero, zero, zero, zero, zero, zero,
                                                                                zero, zero))
        # [3] Adami's pressure (gravity with GRAVITY; a fixed wall has no acceleration) and velocity
        p = real(0.0)
        v_x = v_y = v_z = real(0.0)
        if sum_w > real(0.0):
            g_x = real(P.gravity[0]) if GRAVITY else real(0.0)
            g_y = real(P.gravity[1]) if GRAVITY else real(0.0)
            g_z = real(P.gravity[2]) if GRAVITY else real(0.0)
            p = (sum_p + (g_x * sum_rho_r_x + g_y * sum_rho_r_y + g_z * sum_rho_r_z)) / sum_w
            if NO_SLIP:
                v_x = -sum_v_x / sum_w
                v_y = -sum_v_y / sum_w
                v_z = -sum_v_z / sum_w
        if not CONTINUITY:
            p = max(p, real(0.0))
        # [4] store
        particle_p[i] = p
        particle_rho[i] = wall_density(P, p)
        particle_v[i, 0] = v_x
        particle_v[i, 1] = v_y
        particle_v[i, 2] = v_z
        particle_v[i, 3] = real(0.0)

    return launcher(wall_pressure_main)
