// The pressure term of the momentum equation, one pair's share (compute_forces.comp sums it over the walk).
// Monaghan 1992 (Annu. Rev. Astron. Astrophys. 30, eq. 3.3), the symmetric form
//     a_i = -sum_j m (p_i / rho_i^2 + p_j / rho_j^2) grad_i W_ij,
// which conserves momentum and energy with summation or continuity density. With the kernels' shape
// (kernels.glsl: m grad_i W_ij = -P.pressure_coef grad r_hat) the pair's term is fp r_hat, fp returned here.
// Mueller et al. (2003) and seed 1 use m (p_i + p_j) / (2 rho_j): that estimates grad p / 2, so a column at
// rest settles at twice its hydrostatic pressure. Under DFSPH the pressure is the solver's (dfsph.glsl).
// Mirror: sphcore/sph/pressure.py (same names, same statements).

#include "real.glsl"

// fp of the pair (i, j): pi_rho2 = p_i / rho_i^2, `grad` the pair's kernel gradient (kernels.glsl: pair_gradient).
real pressure_monaghan(real pi_rho2, real pj, real rhoj, real grad) {
    return P.pressure_coef * (pi_rho2 + pj / (rhoj * rhoj)) * grad;
}
