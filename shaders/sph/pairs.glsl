// The direction of a pair in the pair loops (compute_density's continuity rate, compute_forces, the
// DFSPH stages), from neighbour j, or its image across the mirror planes whose bits are set in
// `image`, to particle i. Mirror: sphcore/sph/pairs.py (same names, same statements).

#include "real.glsl"

// r = x_i - x_k and rlen = |r|. Where the two coincide (rlen = 0) the direction is still defined,
// so that the pair's force is not lost: an image lies along its plane's inward normal (`inward`,
// obstacles.glsl: near_obstacles), two particles along x, antisymmetrically in (i, j). The usual case
// returns first (on the CPU the coincident cases' tests cost a third of a list sweep otherwise).
real3 pair_direction(real3 r, real rlen, uint i, uint j, uint image, real3 inward) {
    if (rlen > real(0.0)) {
        real inv = real(1.0) / rlen;  // (one division and three products: on the CPU a tenth of compute_forces)
        return r * inv;
    }
    real3 r_hat = real3(i < j ? -1.0 : 1.0, 0.0, 0.0);
    if ((image & 1u) != 0u) r_hat = real3(inward.x, 0.0, 0.0);
    if ((image & 2u) != 0u) r_hat = real3(0.0, inward.y, 0.0);
    if ((image & 4u) != 0u) r_hat = real3(0.0, 0.0, inward.z);
    return r_hat;
}
