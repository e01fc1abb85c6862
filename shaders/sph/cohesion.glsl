// Surface tension by cohesion, one pair's share (compute_forces.comp sums it over the walk): Becker &
// Teschner 2007 (Weakly compressible SPH for free surface flows, SCA, eq. 11),
//     a_i = -kappa sum_j m W(r_ij) (x_i - x_j)    (equal masses),
// folded as a_i = P.cohesion_coef * sum_j kernel_w(r2) r (sphcore/params.py). Between real particles only
// (image 0): the walls are not wetted.
// Mirror: sphcore/sph/cohesion.py (same names, same statements).

#include "real.glsl"

// The pair's term kernel_w(r2) r, r = x_i - x_j.
real3 cohesion_becker(real r2, real3 r) {
    return kernel_w(r2) * r;
}
