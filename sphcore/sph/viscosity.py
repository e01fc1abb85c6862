"""Viscosity models, chosen by the closure constant VISCOSITY_MODEL (scene key physics.viscosity_model).

Mirror of shaders/sph/viscosity.glsl: same names, same statements (the formulas and their papers
are there). VISCOSITY_MODEL 0: laminar (Mueller et al. 2003), coefficient fluid.viscosity;
1: artificial (Monaghan 1992), Pi_ij = -alpha c h (v_ij . r_ij) / (rho_ij (r^2 + 0.01 h^2)) for
approaching pairs, coefficient fluid.alpha. GLSL reads the parameter block as a global `P`; here
it is the first argument. A GLSL vec3 `v` is `v_x, v_y, v_z`; `real` is the shader's `real`.
"""
from functools import lru_cache

import numpy as np
from numba import njit
from sphcore.sph import named

VISCOSITY_MODELS = ("laminar", "artificial")  # scene key physics.viscosity_model -> VISCOSITY_MODEL (index)


@lru_cache(maxsize=None)
def viscosity(spec, real=np.float32):
    VISCOSITY_MODEL = spec.VISCOSITY_MODEL

    @njit
    def laminar_mueller(P, vi_x, vi_y, vi_z, vj_x, vj_y, vj_z, rhoj, lap):
        """The pair's term of sum_j mu m (v_j - v_i) L_ij / rho_j (1 / rho_i is applied after the sum)."""
        fv = P.viscosity_coef / rhoj * lap
        return fv * (vj_x - vi_x), fv * (vj_y - vi_y), fv * (vj_z - vi_z)

    @njit
    def artificial_monaghan(P, vi_x, vi_y, vi_z, vj_x, vj_y, vj_z, r_x, r_y, r_z, r2, rhoi, rhoj, grad,
                            r_hat_x, r_hat_y, r_hat_z):
        """The pair's term of -sum_j m Pi_ij grad_i W_ij; 0 for receding pairs and at r = 0."""
        vr = (vi_x - vj_x) * r_x + (vi_y - vj_y) * r_y + (vi_z - vj_z) * r_z
        if vr >= real(0.0):
            return real(0.0), real(0.0), real(0.0)
        pi_ij = -P.viscosity_coef * vr / (real(0.5) * (rhoi + rhoj) * (r2 + real(0.01) * P.h2))
        return (pi_ij * P.pressure_coef * grad * r_hat_x, pi_ij * P.pressure_coef * grad * r_hat_y,
                pi_ij * P.pressure_coef * grad * r_hat_z)

    @njit
    def viscous_term(P, vi_x, vi_y, vi_z, vj_x, vj_y, vj_z, r_x, r_y, r_z, r2, rhoi, rhoj, grad, lap,
                     r_hat_x, r_hat_y, r_hat_z):
        """The pair's viscous term of the scene's model."""
        if VISCOSITY_MODEL == 1:
            return artificial_monaghan(P, vi_x, vi_y, vi_z, vj_x, vj_y, vj_z, r_x, r_y, r_z, r2, rhoi, rhoj, grad,
                                       r_hat_x, r_hat_y, r_hat_z)
        return laminar_mueller(P, vi_x, vi_y, vi_z, vj_x, vj_y, vj_z, rhoj, lap)

    @njit
    def viscous_acceleration(f_x, f_y, f_z, rhoi):
        """The acceleration from the summed terms: laminar divides by rho_i, artificial is one already."""
        if VISCOSITY_MODEL == 1:
            return f_x, f_y, f_z
        return f_x / rhoi, f_y / rhoi, f_z / rhoi

    return named(laminar_mueller, artificial_monaghan, viscous_term, viscous_acceleration)
