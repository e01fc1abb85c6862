// The equation of state p(rho), chosen by the specialization constant TAIT (scene key
// physics.equation_of_state), used by compute_density (summation) and integrate_density (continuity).
//   linear (seed 1): p = k (rho - rho_0), P.stiffness = k;
//   Tait (Becker & Teschner 2007, seed 2): p = B ((rho / rho_0)^7 - 1), P.stiffness = B = rho_0 k / 7,
//     the power by multiplications.
// With summation density (CONTINUITY false) p is clamped at 0 so that the free surface, where the kernel
// sum falls short, does not pull (tensile instability); attraction, where a scene wants it, comes from
// the cohesion term. A continuity density has no such deficit and keeps its negative pressures
// (engineering WCSPH, as DualSPHysics): a fluid pulled apart after an impact feels it.
// Mirror: sphcore/sph/equation_of_state.py (same names, same statements).

#include "real.glsl"

real equation_of_state(real rho) {
    real p = P.stiffness * (rho - P.rest_density);
    if (TAIT) {
        real ratio = rho / P.rest_density;
        real ratio2 = ratio * ratio;
        real ratio4 = ratio2 * ratio2;
        p = P.stiffness * (ratio4 * ratio2 * ratio - real(1.0));
    }
    if (!CONTINUITY) p = max(p, real(0.0));
    return p;
}
