// HistoPyramid over the cubes' vertex counts, in one buffer: level 0 (one count per cube)
// first; each level above holds the sums of 8 consecutive nodes of the level below, up to one
// node, the total (as shaders/sph/cells.glsl's pyramid over the cells).
// Mirror: sphcore/mc/pyramid.py (same names, same statements).

// Offset of HistoPyramid level l in the pyramid buffer, and its node count.
uint level_offset(uint l) {
    uint offset = 0u;
    uint size = P.cube_total;
    for (uint k = 0u; k < l; ++k) {
        offset += size;
        size = (size + 7u) / 8u;
    }
    return offset;
}

uint level_size(uint l) {
    uint size = P.cube_total;
    for (uint k = 0u; k < l; ++k) {
        size = (size + 7u) / 8u;
    }
    return size;
}
