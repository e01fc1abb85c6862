// HistoPyramid helpers shared by the neighbour grid (over the cells' particle counts) and by
// marching cubes (over the cubes' vertex counts): one buffer holds level 0, `base` nodes,
// first; each level above holds the sums of 8 consecutive nodes of the level below, up to one
// node, the total.
// Mirror: sphcore/pyramid.py (same names, same statements).

// Offset of HistoPyramid level l in the pyramid buffer, and its node count.
uint level_offset(uint base, uint l) {
    uint offset = 0u;
    uint size = base;
    for (uint k = 0u; k < l; ++k) {
        offset += size;
        size = (size + 7u) / 8u;
    }
    return offset;
}

uint level_size(uint base, uint l) {
    uint size = base;
    for (uint k = 0u; k < l; ++k) {
        size = (size + 7u) / 8u;
    }
    return size;
}
