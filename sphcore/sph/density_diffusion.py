"""Density diffusion of the continuity density (delta-SPH), chosen by the closure constant
DENSITY_DIFFUSION (0: none, 1: Molteni & Colagrossi 2009, 2: Fourtakas et al. 2019).

Mirror of shaders/sph/density_diffusion.glsl: same names, same statements (the formulas, their
papers and the sign conventions are there). GLSL reads the parameter block as a global `P`; here
it is the first argument. A GLSL vec3 `v` is `v_x, v_y, v_z`; `real` is the shader's `real`.
"""
from functools import lru_cache

import numpy as np
from numba import njit

from sphcore.sph import named
from sphcore.sph.kernels import kernels


@lru_cache(maxsize=None)
def density_diffusion(spec, real=np.float32):
    DENSITY_DIFFUSION = spec.DENSITY_DIFFUSION
    kernel_gradient = kernels(spec, real).kernel_gradient

    @njit
    def hydrostatic_density(P, x_ji_x, x_ji_y, x_ji_z):
        """rho^H_ji, the hydrostatic density difference between j and i (x_ji = x_j - x_i): fourtakas only."""
        if DENSITY_DIFFUSION != 2:
            return real(0.0)
        return P.hydrostatic[0] * x_ji_x + P.hydrostatic[1] * x_ji_y + P.hydrostatic[2] * x_ji_z

    @njit
    def diffusion_term(P, rhoi, rhoj, x_ji_x, x_ji_y, x_ji_z, r2, rlen):
        """One pair's diffusion term (without P.diffusion_coef), at distance rlen = sqrt(r2) < h."""
        rho_ji = rhoj - rhoi - hydrostatic_density(P, x_ji_x, x_ji_y, x_ji_z)
        return rho_ji / rhoj * kernel_gradient(P, r2, rlen) * rlen / (r2 + real(0.01) * P.h2)

    return named(hydrostatic_density, diffusion_term)
