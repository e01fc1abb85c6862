"""Density and pressure, one invocation per particle, all-pairs neighbours.

Mirror of shaders/sph/compute_density.comp: same names, same statement order, same step
labels. A GLSL vec2 local `v` is `v_x, v_y` here.
"""
import numpy as np
from numba import njit

from sphcore.workgroups import launcher

f32 = np.float32


@njit
def compute_density_main(i, params, particle_x, particle_rho, particle_p):
    P = params[0]
    # [1] one invocation per particle; the grid is rounded up to whole work groups
    if i >= P.n:
        return
    # [2] own position
    xi_x = particle_x[i, 0]
    xi_y = particle_x[i, 1]
    # [3] wall images: within h of a wall, particle i also sees every particle mirrored
    #     across that wall (ghost fluid: free-slip boundary of Takeda et al. 1994)
    wall_x = P.box_min[0] if xi_x - P.box_min[0] < P.h else P.box_max[0]
    wall_y = P.box_min[1] if xi_y - P.box_min[1] < P.h else P.box_max[1]
    images_x = 2 if abs(xi_x - wall_x) < P.h else 1
    images_y = 2 if abs(xi_y - wall_y) < P.h else 1
    # [4] sum (h^2 - r^2)^3 over all particles and their images within h, self included
    sum_w = f32(0.0)
    for j in range(P.n):
        xj_x = particle_x[j, 0]
        xj_y = particle_x[j, 1]
        for mx in range(images_x):
            for my in range(images_y):
                xk = xj_x if mx == 0 else f32(2.0) * wall_x - xj_x
                yk = xj_y if my == 0 else f32(2.0) * wall_y - xj_y
                r_x = xi_x - xk
                r_y = xi_y - yk
                r2 = r_x * r_x + r_y * r_y
                if r2 < P.h2:
                    q = P.h2 - r2
                    sum_w += q * q * q
    # [5] rho_i = m sum_j W_poly6(r_ij, h)
    rho = P.density_coef * sum_w
    # [6] linear equation of state p = k (rho - rho_0), clamped at 0 so the free surface does not pull
    p = max(P.stiffness * (rho - P.rest_density), f32(0.0))
    # [7] store
    particle_rho[i] = rho
    particle_p[i] = p


compute_density = launcher(compute_density_main)
