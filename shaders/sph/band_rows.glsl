// The rows a rank's pick reads (sphcore.parallel), as pick_groups.comp wrote them after the step's sort: band_rows[0].x
// the pick's entries, band_rows[1 + e] entry e's first row and count. compute_forces' first pass and pick_rows take
// them, one invocation a row (an indirect dispatch of as many), the second pass the others. Needs BandRows bound.
// Mirror: sphcore/sph/band_rows.py (same names, same statements).

// The row of invocation k: entry after entry, each entry's rows in order (false past the last); e its entry.
bool band_row_at(uint k, out uint i, out uint e) {
    i = 0u;
    for (e = 0u; e < band_rows[0].x; e++) {
        if (k < band_rows[1u + e].y) {
            i = band_rows[1u + e].x + k;
            return true;
        }
        k -= band_rows[1u + e].y;
    }
    return false;
}

// Whether row i is one of them.
bool band_row(uint i) {
    for (uint e = 0u; e < band_rows[0].x; e++) {
        if (i >= band_rows[1u + e].x && i - band_rows[1u + e].x < band_rows[1u + e].y) return true;
    }
    return false;
}
