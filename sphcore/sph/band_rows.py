"""The rows a rank's pick reads (sphcore.parallel), as pick_groups wrote them after the step's sort: band_rows[0, 0]
the pick's entries, band_rows[1 + e] entry e's first row and count. The shader says more.

Mirror of shaders/sph/band_rows.glsl: same names, same statements (the buffer passed in; the GLSL out parameters
returned).
"""
import numpy as np
from numba import njit


@njit
def band_row_at(k, band_rows):
    """The row of invocation k: entry after entry, each entry's rows in order; (found, row, entry)."""
    i = 0
    for e in range(np.int64(band_rows[0, 0])):
        if k < np.int64(band_rows[1 + e, 1]):
            i = np.int64(band_rows[1 + e, 0]) + k
            return True, i, e
        k -= np.int64(band_rows[1 + e, 1])
    return False, i, np.int64(band_rows[0, 0])


@njit
def band_row(i, band_rows):
    """Whether row i is one of them."""
    for e in range(np.int64(band_rows[0, 0])):
        if i >= np.int64(band_rows[1 + e, 0]) and i - np.int64(band_rows[1 + e, 0]) < np.int64(band_rows[1 + e, 1]):
            return True
    return False
