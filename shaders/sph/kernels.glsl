// Smoothing kernels, chosen by the specialization constant KERNEL (scene key physics.kernel): each
// helper returns the kernel's shape only; its normalisation, times the particle mass (and mu for
// the viscosity), is folded on the host into the parameter block (sphcore/params.py:
// kernel_coefficients, fold_parameters). With r_ij = x_i - x_j, r = |r_ij|, r_hat = r_ij / r:
//     m W_ij                = P.density_coef   * kernel_w(r2)
//     m grad_i W_ij         = -P.pressure_coef * kernel_gradient(r2, r) * r_hat   (so F = -coef G / r)
//     mu m L_ij             = P.viscosity_coef * kernel_laplacian(r2, r)
// where L_ij > 0 is what the laminar viscosity mu sum_j m (v_j - v_i) / (rho_i rho_j) L_ij needs.
// The support radius is h (P.h) for every kernel: the neighbour grid's cell size.
//   KERNEL 0, "mueller" (Mueller, Charypar & Gross 2003): W = poly6 ~ (h^2 - r^2)^3, grad W from
//     spiky ~ (h - r)^2, L = lap W_visc ~ (h - r).
//   KERNEL 1, "wendland_c2" (Wendland 1995; Dehnen & Aly 2012), q = r / h:
//     W = sigma (1 - q)^4 (1 + 4 q), sigma = 7 / (pi h^2) in 2D, 21 / (2 pi h^3) in 3D;
//     dW/dr = -(20 sigma / h) q (1 - q)^3, so kernel_gradient = q (1 - q)^3;
//     L = -2 (r_ij . grad_i W_ij) / (r^2 + 0.01 h^2) (Morris, Fox & Zhu 1997)
//       = (2 * 20 sigma / h) q (1 - q)^3 r / (r^2 + 0.01 h^2).
// Mirror: sphcore/sph/kernels.py (same names, same statements).

#include "real.glsl"

// W's shape at squared distance r2 (< h^2): m W_ij = P.density_coef * kernel_w(r2).
real kernel_w(real r2) {
    if (KERNEL == 1u) {
        real q = sqrt(r2) / P.h;
        real t = real(1.0) - q;
        real t2 = t * t;
        return t2 * t2 * (real(1.0) + real(4.0) * q);
    }
    real d = P.h2 - r2;
    return d * d * d;
}

// The gradient's magnitude (shape), at distance rlen = sqrt(r2) < h:
// m grad_i W_ij = -P.pressure_coef * kernel_gradient(r2, rlen) * r_hat_ij.
real kernel_gradient(real r2, real rlen) {
    if (KERNEL == 1u) {
        real q = rlen / P.h;
        real t = real(1.0) - q;
        return q * t * t * t;
    }
    real hr = P.h - rlen;
    return hr * hr;
}

// The gradient's magnitude for particle i and neighbour j or its mirror image (image != 0: its bits
// name the walls and obstacle faces it is mirrored across): the pair loops' gradient. An image moves
// with its particle, so i and its own image cannot spread apart as a free pair does. Wendland C2's
// gradient vanishes as r -> 0 (its magnitude peaks at q = 1/4), so the push of a wall on a particle
// coming closer than h/8 to it would fade, and the particle would be held on the wall, where the images
// of its neighbours balance it (a dam break's floor and far wall collected 8 % of the particles).
// For an image the magnitude is therefore held at its peak below q = 1/4; at rest (a particle dx/2 from
// the wall, h = 2 or 4 dx) nothing changes. Mueller's spiky gradient peaks at r = 0 already.
real pair_gradient(real r2, real rlen, uint image) {
    if (KERNEL == 1u && image != 0u) rlen = max(rlen, real(0.25) * P.h);
    return kernel_gradient(r2, rlen);
}

// The laminar viscosity's kernel (shape, > 0) at distance rlen = sqrt(r2) < h:
// mu m L_ij = P.viscosity_coef * kernel_laplacian(r2, rlen).
real kernel_laplacian(real r2, real rlen) {
    if (KERNEL == 1u) return kernel_gradient(r2, rlen) * rlen / (r2 + real(0.01) * P.h2);
    return P.h - rlen;
}
