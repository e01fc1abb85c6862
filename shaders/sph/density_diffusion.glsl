// Density diffusion of the continuity density (delta-SPH), chosen by the specialization constant
// DENSITY_DIFFUSION (scene key physics.density_diffusion; 0: none, the term is compiled out):
//     D_i = delta h_s c_0 sum_j psi_ij . grad_i W_ij V_j,   V_j = m / rho_j,   h_s = h / 2,
// folded as D_i = P.diffusion_coef * sum_j diffusion_term(...) (sphcore/params.py: fold_parameters).
//   1, "molteni" (Molteni & Colagrossi 2009): psi_ij = 2 (rho_j - rho_i) r_ji / |r_ij|^2.
//   2, "fourtakas" (Fourtakas et al. 2019): psi_ij = 2 (rho_j - rho_i - rho^H_ji) r_ji / |r_ij|^2: the
//     hydrostatic density difference rho^H_ji = rho_0 g . (x_j - x_i) / c^2 (P.hydrostatic) is taken out,
//     so a fluid at hydrostatic rest diffuses nothing (Molteni's term pulls it towards uniform density:
//     the column sinks). For Tait, Fourtakas et al. write rho_0 ((1 + rho_0 g z_ij / B)^(1/7) - 1);
//     this is its first order in g z / c^2 (exact for the linear law; off by 3/7 of s = 7 g z / c^2 of
//     itself, under 1 % within a kernel at c >= 10 sqrt(g H)).
// |r_ij|^2 is regularised by 0.01 h^2, as in Morris et al. 1997's Laplacian (kernels.glsl).
// With r_ji . m grad_i W_ij = P.pressure_coef kernel_gradient(r) r (kernels.glsl), one pair's term is
//     (rho_j - rho_i - rho^H_ji) / rho_j * kernel_gradient(r2, r) r / (r2 + 0.01 h^2).
// Signs checked against DualSPHysics (JSphGpu_ker.cu, DDT_DDT and DDT_DDT2) and TrixiParticles.jl
// (density_diffusion.jl), by the test that a hydrostatic column diffuses nothing with fourtakas.
// Mirror: sphcore/sph/density_diffusion.py (same names, same statements).

#include "real.glsl"

// rho^H_ji, the hydrostatic density difference between j and i (x_ji = x_j - x_i): fourtakas only.
real hydrostatic_density(real3 x_ji) {
    if (DENSITY_DIFFUSION != 2u) return real(0.0);
    return P.hydrostatic.x * x_ji.x + P.hydrostatic.y * x_ji.y + P.hydrostatic.z * x_ji.z;
}

// One pair's diffusion term (without P.diffusion_coef), at distance rlen = sqrt(r2) < h.
real diffusion_term(real rhoi, real rhoj, real3 x_ji, real r2, real rlen) {
    real rho_ji = rhoj - rhoi - hydrostatic_density(x_ji);
    return rho_ji / rhoj * kernel_gradient(r2, rlen) * rlen / (r2 + real(0.01) * P.h2);
}
