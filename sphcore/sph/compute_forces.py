"""Acceleration from pressure (spiky gradient), viscosity (Mueller et al. 2003) and gravity,
one invocation per particle, all-pairs neighbours, mirror images at the walls.

Mirror of shaders/sph/compute_forces.comp: same names, same statement order, same step
labels. A GLSL vec2 local `v` is `v_x, v_y` here.
"""
import numpy as np
from numba import njit

from sphcore.workgroups import launcher

f32 = np.float32


@njit
def compute_forces_main(i, params, particle_x, particle_v, particle_a, particle_rho, particle_p):
    P = params[0]
    # [1] one invocation per particle; the grid is rounded up to whole work groups
    if i >= P.n:
        return
    # [2] own state
    xi_x = particle_x[i, 0]
    xi_y = particle_x[i, 1]
    vi_x = particle_v[i, 0]
    vi_y = particle_v[i, 1]
    rhoi = particle_rho[i]
    pi = particle_p[i]
    pi_rho2 = pi / (rhoi * rhoi)
    # [3] wall images, as in compute_density; an image's normal velocity is reversed (free slip)
    wall_x = P.box_min[0] if xi_x - P.box_min[0] < P.h else P.box_max[0]
    wall_y = P.box_min[1] if xi_y - P.box_min[1] < P.h else P.box_max[1]
    images_x = 2 if abs(xi_x - wall_x) < P.h else 1
    images_y = 2 if abs(xi_y - wall_y) < P.h else 1
    # [4] pressure acceleration and viscous force density summed over all other particles and all images within h
    f_pressure_x = f32(0.0)
    f_pressure_y = f32(0.0)
    f_viscosity_x = f32(0.0)
    f_viscosity_y = f32(0.0)
    for j in range(P.n):
        xj_x = particle_x[j, 0]
        xj_y = particle_x[j, 1]
        vj_x = particle_v[j, 0]
        vj_y = particle_v[j, 1]
        rhoj = particle_rho[j]
        pj = particle_p[j]
        for mx in range(images_x):
            for my in range(images_y):
                if j == i and mx == 0 and my == 0:
                    continue
                xk = xj_x if mx == 0 else f32(2.0) * wall_x - xj_x
                yk = xj_y if my == 0 else f32(2.0) * wall_y - xj_y
                vk_x = vj_x if mx == 0 else -vj_x
                vk_y = vj_y if my == 0 else -vj_y
                r_x = xi_x - xk
                r_y = xi_y - yk
                r2 = r_x * r_x + r_y * r_y
                if r2 >= P.h2:
                    continue
                rlen = np.sqrt(r2)
                hr = P.h - rlen
                # [5] direction from the neighbour to i. Where the two coincide (normalize(0) is NaN):
                #     an image coincides with i only on a wall, so push along the wall's inward
                #     normal; two particles are pushed apart along x, antisymmetrically in (i, j)
                #     so momentum is conserved
                r_hat_x = f32(-1.0) if i < j else f32(1.0)
                r_hat_y = f32(0.0)
                if mx == 1:
                    r_hat_x = f32(1.0) if wall_x == P.box_min[0] else f32(-1.0)
                    r_hat_y = f32(0.0)
                if my == 1:
                    r_hat_x = f32(0.0)
                    r_hat_y = f32(1.0) if wall_y == P.box_min[1] else f32(-1.0)
                if rlen > f32(0.0):
                    r_hat_x = r_x / rlen
                    r_hat_y = r_y / rlen
                # [6] pressure: -sum_j m (p_i / rho_i^2 + p_j / rho_j^2) grad W_spiky, the form that conserves
                #     momentum and energy with summation density (Monaghan 1992); grad W_spiky = -30/(pi h^5) (h - r)^2 r_hat.
                #     Mueller et al. (2003) and seed 1 use m (p_i + p_j) / (2 rho_j): that estimates grad p / 2,
                #     so a column at rest settles at twice its hydrostatic pressure, and it over-pushes
                #     low-density surface particles, which gains energy in a dam break
                fp = P.pressure_coef * (pi_rho2 + pj / (rhoj * rhoj)) * hr * hr
                f_pressure_x += fp * r_hat_x
                f_pressure_y += fp * r_hat_y
                # [7] viscosity: mu sum_j m (v_j - v_i) / rho_j lap W_visc, lap W_visc = 40/(pi h^5) (h - r)
                fv = P.viscosity_coef / rhoj * hr
                f_viscosity_x += fv * (vk_x - vi_x)
                f_viscosity_y += fv * (vk_y - vi_y)
    # [8] a_i = f_pressure + f_viscosity / rho_i + g (f_pressure is already per unit mass)
    a_x = f_pressure_x + f_viscosity_x / rhoi + P.gravity[0]
    a_y = f_pressure_y + f_viscosity_y / rhoi + P.gravity[1]
    # [9] store
    particle_a[i, 0] = a_x
    particle_a[i, 1] = a_y


compute_forces = launcher(compute_forces_main)
