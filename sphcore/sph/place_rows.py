"""Before a step of a rank of sphcore.parallel whose rows came from GPU to GPU: the rows received from the other
ranks written over the old halo's rows, one invocation per received row. The shader says more.

Mirror of shaders/sph/place_rows.comp: same names, same statement order, same step labels. The received words are
read through a view of the buffers' real type (an even count of words at float64: Rank pads them).
"""
from functools import lru_cache

import numpy as np
from numba import njit

from sphcore.sph.packed_rows import packed_rows, run_words
from sphcore.workgroups import launcher


@lru_cache(maxsize=None)
def place_rows(spec, real=np.float32):
    VERLET = spec.VERLET
    REAL_WORDS = np.dtype(real).itemsize // 4
    migrant_words = packed_rows(spec, real)[0]

    @njit
    def place_rows_main(a, params, particle_x, particle_v, particle_rho, particle_id, particle_vh, received,
                        place_table):
        reals = received.view(real)
        # [1] one invocation per received row
        if a >= np.int64(place_table[0, 3]):
            return
        # [2] its sender: the first whose rows (migrants, then halo) reach past it
        s = 0
        at = 0
        while a >= at + np.int64(place_table[1 + s, 1]) + np.int64(place_table[1 + s, 2]):
            at += np.int64(place_table[1 + s, 1]) + np.int64(place_table[1 + s, 2])
            s += 1
        migrants, halo = np.int64(place_table[1 + s, 1]), np.int64(place_table[1 + s, 2])
        # [3] the runs it is in: the migrants', else past them the halo's
        j = a - at
        w = np.int64(place_table[1 + s, 0])
        count = migrants
        migrant = j < migrants
        if not migrant:
            w += migrant_words(migrants)
            j -= migrants
            count = halo
        # [4] the row it replaces: below the owned rows, else after them
        first, end = np.int64(place_table[0, 1]), np.int64(place_table[0, 2])
        row = a if a < first else a + end - first
        # [5] store
        for c in range(4):  # (a vec4)
            particle_x[row, c] = reals[(w + j * 4 * REAL_WORDS) // REAL_WORDS + c]
        w += run_words(count, 4 * REAL_WORDS)
        for c in range(4):  # (a vec4)
            particle_v[row, c] = reals[(w + j * 4 * REAL_WORDS) // REAL_WORDS + c]
        w += run_words(count, 4 * REAL_WORDS)
        particle_rho[row] = reals[(w + j * REAL_WORDS) // REAL_WORDS]
        w += run_words(count, REAL_WORDS)
        particle_id[row] = received[w + j]
        w += run_words(count, 1)
        if VERLET and migrant:
            for c in range(4):  # (a vec4)
                particle_vh[row, c] = reals[(w + j * 4 * REAL_WORDS) // REAL_WORDS + c]

    return launcher(place_rows_main)
