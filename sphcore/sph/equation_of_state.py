"""The equation of state p(rho): linear or Tait (TAIT); clamped at 0 with summation density only.

Mirror of shaders/sph/equation_of_state.glsl: same names, same statements (the reasons are there).
GLSL reads the parameter block as a global `P`; here it is the first argument.
"""
from functools import lru_cache

import numpy as np
from numba import njit


@lru_cache(maxsize=None)
def equation_of_state(spec, real=np.float32):
    TAIT, CONTINUITY = spec.TAIT, spec.CONTINUITY

    @njit
    def equation_of_state(P, rho):
        """p(rho) of the scene's law."""
        p = P.stiffness * (rho - P.rest_density)
        if TAIT:
            ratio = rho / P.rest_density
            ratio2 = ratio * ratio
            ratio4 = ratio2 * ratio2
            p = P.stiffness * (ratio4 * ratio2 * ratio - real(1.0))
        if not CONTINUITY:
            p = max(p, real(0.0))
        return p

    return equation_of_state
