"""Smoothing kernels, chosen by the closure constant KERNEL (scene key physics.kernel).

Mirror of shaders/sph/kernels.glsl: same names, same statements (the formulas and their papers
are there). Each helper returns the kernel's shape; the normalisation times the mass is folded on
the host (sphcore.params.kernel_coefficients):
    m W_ij        = P.density_coef   * kernel_w(r2)
    m grad_i W_ij = -P.pressure_coef * kernel_gradient(r2, r) * r_hat_ij
    mu m L_ij     = P.viscosity_coef * kernel_laplacian(r2, r)
KERNEL 0: Mueller et al. 2003 (poly6, spiky gradient, viscosity Laplacian); 1: Wendland C2 with
Morris et al. 1997's Laplacian. GLSL reads the parameter block as a global `P`; here it is the
first argument. `real` is the shader's `real` (shaders/sph/real.glsl).
"""
from functools import lru_cache

import numpy as np
from numba import njit
from sphcore.sph import named


@lru_cache(maxsize=None)
def kernels(spec, real=np.float32):
    KERNEL = spec.KERNEL

    @njit
    def kernel_w(P, r2):
        """W's shape at squared distance r2 (< h^2): m W_ij = P.density_coef * kernel_w(r2)."""
        if KERNEL == 1:
            q = np.sqrt(r2) / P.h
            t = real(1.0) - q
            t2 = t * t
            return t2 * t2 * (real(1.0) + real(4.0) * q)
        d = P.h2 - r2
        return d * d * d

    @njit
    def kernel_gradient(P, r2, rlen):
        """The gradient's magnitude (shape): m grad_i W_ij = -P.pressure_coef * kernel_gradient * r_hat_ij."""
        if KERNEL == 1:
            q = rlen / P.h
            t = real(1.0) - q
            return q * t * t * t
        hr = P.h - rlen
        return hr * hr

    @njit
    def pair_gradient(P, r2, rlen, image):
        """The pair loops' gradient for particle i and neighbour j or its mirror image (image != 0):
        Wendland C2's magnitude is held at its peak (q = 1/4) below h/4 for an image, so that a wall
        keeps pushing a particle that comes close to it (kernels.glsl says why)."""
        if KERNEL == 1 and image != 0:
            rlen = max(rlen, real(0.25) * P.h)
        return kernel_gradient(P, r2, rlen)

    @njit
    def kernel_laplacian(P, r2, rlen):
        """The laminar viscosity's kernel (shape, > 0): mu m L_ij = P.viscosity_coef * kernel_laplacian."""
        if KERNEL == 1:
            return kernel_gradient(P, r2, rlen) * rlen / (r2 + real(0.01) * P.h2)
        return P.h - rlen

    return named(kernel_w, kernel_gradient, pair_gradient, kernel_laplacian)
