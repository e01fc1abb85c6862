"""Particle shifting, chosen by the closure constant SHIFTING (0: none, 1: Lind et al. 2012's Fickian shifting,
with Skillen et al. 2013's D = A h_s |v_i| dt and DualSPHysics' free-surface threshold).

Mirror of shaders/sph/shifting.glsl: same names, same statements (the formulas, their papers and the
free-surface treatment are there). GLSL reads the parameter block as a global `P`; here it is the first argument.
A GLSL vec3 `v` is `v_x, v_y, v_z`, a vec4 four values; `real` is the shader's `real`.
"""
from functools import lru_cache

import numpy as np
from numba import njit

from sphcore.sph import named
from sphcore.sph.kernels import kernels

SHIFTINGS = ("none", "lind")  # scene key physics.shifting -> SHIFTING (index)


@lru_cache(maxsize=None)
def shifting(spec, real=np.float32):
    DIM = spec.DIM
    kernel_w = kernels(spec, real).kernel_w

    @njit
    def shifting_lind(P, r2, rlen, rhoj, grad, r_hat_x, r_hat_y, r_hat_z):
        """One pair's terms: (grad C_i, div r_i) of neighbour j (or its image) at distance rlen."""
        g = P.pressure_coef / rhoj * grad
        ratio = kernel_w(P, r2) * P.shifting_w
        ratio2 = ratio * ratio
        # `precise` in the shader (no contraction): computed as written there, as here
        c = -(real(1.0) + real(0.2) * (ratio2 * ratio2)) * g
        return c * r_hat_x, c * r_hat_y, c * r_hat_z, g * rlen

    @njit
    def shift_of(P, sums_x, sums_y, sums_z, sums_w, v_x, v_y, v_z, dt):
        """The displacement of a particle moving at v over a step dt, from its sums (grad C_i, div r_i)."""
        tfs = real(1.5) if DIM == 2 else real(2.75)
        if sums_w <= tfs:
            return real(0.0), real(0.0), real(0.0)
        speed = np.sqrt(v_x * v_x + v_y * v_y + v_z * v_z)
        d = -P.shifting_coef * speed * dt * min((sums_w - tfs) / (real(DIM) - tfs), real(1.0))
        return d * sums_x, d * sums_y, d * sums_z

    return named(shifting_lind, shift_of)
