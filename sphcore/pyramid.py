"""HistoPyramid helpers shared by the neighbour grid (over the cells' particle counts) and by
marching cubes (over the cubes' vertex counts): one buffer holds level 0, `base` nodes,
first; each level above holds the sums of 8 consecutive nodes of the level below, up to one
node, the total.

Mirror of shaders/pyramid.glsl: same names, same statements.
"""
from numba import njit


@njit(inline="always")
def level_offset(base, l):
    """Offset of HistoPyramid level l in the pyramid buffer."""
    offset = 0
    size = int(base)
    for k in range(l):
        offset += size
        size = (size + 7) // 8
    return offset


@njit(inline="always")
def level_size(base, l):
    """Node count of HistoPyramid level l."""
    size = int(base)
    for k in range(l):
        size = (size + 7) // 8
    return size
