// Viscosity models, chosen by the specialization constant VISCOSITY_MODEL (scene key
// physics.viscosity_model); compute_forces.comp sums `viscous_term` over the neighbours (wall and
// obstacle images included, their velocity from walls.glsl) and turns the sum into an acceleration
// with `viscous_acceleration`. With v_ij = v_i - v_j, r_ij = x_i - x_j, r = |r_ij|, r_hat = r_ij / r,
// and the kernels' shapes of kernels.glsl (`grad`: m grad_i W_ij = -P.pressure_coef grad r_hat;
// `lap`: mu m L_ij = P.viscosity_coef lap):
//   VISCOSITY_MODEL 0, "laminar" (Mueller, Charypar & Gross 2003): a_i = mu sum_j m (v_j - v_i) L_ij
//     / (rho_i rho_j), coefficient fluid.viscosity (mu, folded into P.viscosity_coef).
//   VISCOSITY_MODEL 1, "artificial" (Monaghan 1992, eq. 4.2; DualSPHysics' "Artificial"):
//     a_i = -sum_j m Pi_ij grad_i W_ij, Pi_ij = -alpha c h (v_ij . r_ij) / (rho_ij (r^2 + 0.01 h^2))
//     for approaching pairs (v_ij . r_ij < 0), else 0; rho_ij = (rho_i + rho_j) / 2, alpha c h =
//     P.viscosity_coef (fluid.alpha, c = sqrt(fluid.stiffness)). Pi_ij is symmetric in (i, j) and
//     grad_i W_ij antisymmetric, so momentum is conserved pair by pair. h is the kernel's support radius
//     (as everywhere here): codes whose h is the smoothing length, half the support of Wendland C2
//     (DualSPHysics, TrixiParticles), get the same Pi_ij with twice our alpha. Its shear viscosity is
//     nu = alpha c h / (2 dim + 4) (Monaghan 2005), the dam break's laminar mu = alpha rho_0 c h / (2 dim + 4).
// Mirror: sphcore/sph/viscosity.py (same names, same statements).

#include "real.glsl"

// Laminar: the pair's term of sum_j mu m (v_j - v_i) L_ij / rho_j (1 / rho_i is applied once, after the sum).
real3 laminar_mueller(real3 vi, real3 vj, real rhoj, real lap) {
    real fv = P.viscosity_coef / rhoj * lap;
    return fv * (vj - vi);
}

// Artificial: the pair's term of -sum_j m Pi_ij grad_i W_ij (an acceleration); 0 for receding pairs
// and at r = 0, where v_ij . r_ij = 0.
real3 artificial_monaghan(real3 vi, real3 vj, real3 r, real r2, real rhoi, real rhoj, real grad, real3 r_hat) {
    real vr = (vi.x - vj.x) * r.x + (vi.y - vj.y) * r.y + (vi.z - vj.z) * r.z;
    if (vr >= real(0.0)) return real3(0.0);
    real pi_ij = -P.viscosity_coef * vr / (real(0.5) * (rhoi + rhoj) * (r2 + real(0.01) * P.h2));
    return pi_ij * P.pressure_coef * grad * r_hat;
}

// The pair's viscous term of the scene's model.
real3 viscous_term(real3 vi, real3 vj, real3 r, real r2, real rhoi, real rhoj, real grad, real lap, real3 r_hat) {
    if (VISCOSITY_MODEL == 1u) return artificial_monaghan(vi, vj, r, r2, rhoi, rhoj, grad, r_hat);
    return laminar_mueller(vi, vj, rhoj, lap);
}

// The acceleration from the summed terms: laminar divides by rho_i, artificial is one already.
real3 viscous_acceleration(real3 f, real rhoi) {
    if (VISCOSITY_MODEL == 1u) return f;
    return f / rhoi;
}
