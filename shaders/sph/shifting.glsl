// Particle shifting, chosen by the specialization constant SHIFTING (scene key physics.shifting; 0: "none", the
// term is compiled out; 1: "lind"). Fickian shifting of Lind et al. 2012 (J. Comput. Phys. 231, 1499, eqs. 8-10,
// with the tensile-instability correction of their eq. 18):
//     dr_i = -D grad C_i,   grad C_i = sum_j (1 + R (W_ij / W(dx))^n) grad_i W_ij V_j,   R = 0.2, n = 4,
// with V_j = m / rho_j and the diffusion coefficient of Skillen et al. 2013 (CMAME 265, eq. 32),
//     D = A h_s |v_i| dt,   h_s = h / 2 (the smoothing length, as density_diffusion.glsl's),
// A = fluid.shifting (DualSPHysics' ShiftCoef, -2 there with the sign folded in). P.shifting_coef = A h_s and
// P.shifting_w = 1 / kernel_w(dx^2) are folded on the host (sphcore/params.py).
// Free surface, as DualSPHysics 4 (JSphGpu_ker.cu: KerRunShifting, ShiftTFS; Mokos 2017's thesis): the position
// divergence div r_i = -sum_j r_ij . grad_i W_ij V_j is dim inside the fluid and falls towards the surface; below
// TFS (1.5 in 2D, 2.75 in 3D, DualSPHysics' values) a particle is not shifted, above it the shift is scaled by
// (div r_i - TFS) / (dim - TFS), so a surface particle is not pushed out of the fluid. Wall and obstacle images
// count as fluid (ghost particles): next to a wall the sums are whole.
// compute_forces sums shifting_lind over its walk (one call per pair) and stores (grad C_i, div r_i) in
// particle_shift; integrate moves the particle by shift_of after its drift.
// With kernels.glsl's shapes, V_j grad_i W_ij = -P.pressure_coef / rho_j grad r_hat (grad: pair_gradient), so
// r_ij . V_j grad_i W_ij = -P.pressure_coef / rho_j grad |r_ij|.
// Mirror: sphcore/sph/shifting.py (same names, same statements).

#include "real.glsl"

// One pair's terms: (grad C_i, div r_i) of neighbour j (or its image) at distance rlen, direction r_hat.
real4 shifting_lind(real r2, real rlen, real rhoj, real grad, real3 r_hat) {
    real g = P.pressure_coef / rhoj * grad;
    real ratio = kernel_w(r2) * P.shifting_w;
    real ratio2 = ratio * ratio;
    // `precise` (NoContraction, as dfsph_residual.comp's): unmarked, lavapipe's compiler fused or distributed
    // 1 + 0.2 ratio^4 with g, the last bit of grad C_i moved, and the backends parted from the second step of a
    // dam break (tests/test_shifting.py)
    precise real c = -(real(1.0) + real(0.2) * (ratio2 * ratio2)) * g;
    return real4(c * r_hat, g * rlen);
}

// The displacement of a particle moving at v over a step dt, from its sums (grad C_i, div r_i).
real3 shift_of(real4 sums, real3 v, float dt) {
    real tfs = DIM == 2u ? real(1.5) : real(2.75);
    if (sums.w <= tfs) return real3(0.0);
    real speed = sqrt(v.x * v.x + v.y * v.y + v.z * v.z);
    real d = -P.shifting_coef * speed * dt * min((sums.w - tfs) / (real(DIM) - tfs), real(1.0));
    return d * sums.xyz;
}
