"""The pressure term of the momentum equation, one pair's share: Monaghan 1992's symmetric form
a_i = -sum_j m (p_i / rho_i^2 + p_j / rho_j^2) grad_i W_ij.

Mirror of shaders/sph/pressure.glsl: same names, same statements (the formula and its paper are there).
GLSL reads the parameter block as a global `P`; here it is the first argument.
"""
from functools import lru_cache

import numpy as np
from numba import njit


@lru_cache(maxsize=None)
def pressure(real=np.float32):

    @njit
    def pressure_monaghan(P, pi_rho2, pj, rhoj, grad):
        """fp of the pair (i, j): the term is fp r_hat (pi_rho2 = p_i / rho_i^2, grad: kernels.pair_gradient)."""
        return P.pressure_coef * (pi_rho2 + pj / (rhoj * rhoj)) * grad

    return pressure_monaghan
