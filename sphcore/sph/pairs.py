"""The direction of a pair in the pair loops, from neighbour j (or its image across the mirror
planes whose bits are set in `image`) to particle i, defined also where the two coincide.

Mirror of shaders/sph/pairs.glsl: same names, same statements. A GLSL vec3 `v` is `v_x, v_y, v_z`.
"""
from functools import lru_cache

import numpy as np
from numba import njit


@lru_cache(maxsize=None)
def pairs(real=np.float32):

    @njit
    def pair_direction(r_x, r_y, r_z, rlen, i, j, image, inward_x, inward_y, inward_z):
        if rlen > real(0.0):
            inv = real(1.0) / rlen  # (one division and three products: on the CPU a tenth of compute_forces)
            return r_x * inv, r_y * inv, r_z * inv
        r_hat_x = real(-1.0) if i < j else real(1.0)
        r_hat_y = real(0.0)
        r_hat_z = real(0.0)
        if (image & 1) != 0:
            r_hat_x, r_hat_y, r_hat_z = inward_x, real(0.0), real(0.0)
        if (image & 2) != 0:
            r_hat_x, r_hat_y, r_hat_z = real(0.0), inward_y, real(0.0)
        if (image & 4) != 0:
            r_hat_x, r_hat_y, r_hat_z = real(0.0), real(0.0), inward_z
        return r_hat_x, r_hat_y, r_hat_z

    return pair_direction
