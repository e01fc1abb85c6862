// The grid's cell ranges (cells.glsl: range_count, range_cells) as ranges of sorted particles, for the scans
// (walk.glsl, sample_gauges.comp). An include of its own, not part of cells.glsl: it reads cell_start and
// cell_pyramid, which the including shader declares after cells.glsl and before this file.
// Mirror: sphcore/sph/cell_ranges.py (same names, same statements).

// Sorted particles [start, end) of range k around cell `base`, or every particle without the grid; false where
// the range is outside the box.
bool cell_range(ivec3 base, uint k, out uint start, out uint end) {
    start = 0u;
    end = P.n;
    if (!GRID) return true;
    int first;
    int last;
    if (!range_cells(base, k, first, last)) return false;
    start = cell_start[first];
    end = cell_start[last] + cell_pyramid[last];
    return true;
}
