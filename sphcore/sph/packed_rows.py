"""The layout of a rank's rows for another rank (sphcore.parallel; pack_rows writes it, place_rows reads it): a
sender's migrants' runs, then its halo's, each run of a buffer's rows from a multiple of 16 bytes, in words.

Mirror of shaders/sph/packed_rows.glsl: same names, same statements.
"""
from functools import lru_cache

import numpy as np
from numba import njit


@njit
def run_words(rows, words):
    """The words of a run of `rows` rows of `words` words each, from a multiple of 16 bytes (4 words)."""
    return (rows * words + 3) // 4 * 4


@lru_cache(maxsize=None)
def packed_rows(spec, real=np.float32):
    """(migrant_words, halo_words) of `spec`'s rows at precision `real`."""
    VERLET = spec.VERLET
    REAL_WORDS = np.dtype(real).itemsize // 4

    @njit
    def halo_words(halo):
        """The words of the halo's runs of `halo` rows."""
        return 2 * run_words(halo, 4 * REAL_WORDS) + run_words(halo, REAL_WORDS) + run_words(halo, 1)

    @njit
    def migrant_words(migrants):
        """The words of the migrants' runs of `migrants` rows (the halo's, and Verlet's half-step velocity): where
        the halo's start."""
        words = halo_words(migrants)
        if VERLET:
            words += run_words(migrants, 4 * REAL_WORDS)
        return words

    return migrant_words, halo_words
