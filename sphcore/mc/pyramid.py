"""HistoPyramid over the cubes' vertex counts, in one buffer: level 0 (one count per cube)
first; each level above holds the sums of 8 consecutive nodes of the level below, up to one
node, the total (as shaders/sph/cells.glsl's pyramid over the cells).

Mirror of shaders/mc/pyramid.glsl: same names, same statements.
"""
from numba import njit


@njit(inline="always")
def level_offset(P, l):
    """Offset of HistoPyramid level l in the pyramid buffer."""
    offset = 0
    size = int(P.cube_total)
    for k in range(l):
        offset += size
        size = (size + 7) // 8
    return offset


@njit(inline="always")
def level_size(P, l):
    """Node count of HistoPyramid level l."""
    size = int(P.cube_total)
    for k in range(l):
        size = (size + 7) // 8
    return size
