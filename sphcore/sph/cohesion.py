"""Surface tension by cohesion, one pair's share: Becker & Teschner 2007,
a_i = -kappa sum_j m W(r_ij) (x_i - x_j), folded as P.cohesion_coef * sum_j kernel_w(r2) r.

Mirror of shaders/sph/cohesion.glsl: same names, same statements (the formula and its paper are there).
GLSL reads the parameter block as a global `P`; here it is the first argument. A GLSL vec3 `v` is
`v_x, v_y, v_z`.
"""
from functools import lru_cache

import numpy as np
from numba import njit

from sphcore.sph.kernels import kernels


@lru_cache(maxsize=None)
def cohesion(spec, real=np.float32):
    kernel_w = kernels(spec, real).kernel_w

    @njit
    def cohesion_becker(P, r2, r_x, r_y, r_z):
        """The pair's term kernel_w(r2) r, r = x_i - x_j."""
        w = kernel_w(P, r2)
        return w * r_x, w * r_y, w * r_z

    return cohesion_becker
