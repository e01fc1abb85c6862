// The rows whose density a rank of sphcore.parallel sums (P.owned_end > 0: compute_density): those whose coordinate
// along the slab axis lies in P.summed_min .. summed_max, its slab widened by a reach less than the halo's depth
// (sphcore.decomposition.summed_width). A step reads the densities and pressures of the particles within a reach of
// an owned one or of a gauge's point in the slab (with bodies: of the fluid within a reach of a wall particle within
// a reach of those): the halo's outermost reach is held for those densities' sums alone. Every row on one process
// (owned_end 0).
// Mirror: sphcore/sph/summed.py (same names, same statements).

bool summed_row(real coordinate) {
    return P.owned_end == 0u || (coordinate >= real(P.summed_min) && coordinate < real(P.summed_max));
}
