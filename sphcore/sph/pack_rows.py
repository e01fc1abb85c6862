"""After a step of a rank of sphcore.parallel whose rows go from GPU to GPU: the rows pick_rows packed into the
scratch buffers, written into `sent` as each other rank takes them, one invocation per row sent. The shader says more.

Mirror of shaders/sph/pack_rows.comp: same names, same statement order, same step labels. The words are written
through a view of the buffers' real type (every run starts on 16 bytes).
"""
from functools import lru_cache

import numpy as np
from numba import njit

from sphcore.sph.packed_rows import packed_rows, run_words
from sphcore.workgroups import launcher


@lru_cache(maxsize=None)
def pack_rows(spec, real=np.float32):
    VERLET = spec.VERLET
    REAL_WORDS = np.dtype(real).itemsize // 4
    migrant_words = packed_rows(spec, real)

    @njit
    def pack_rows_main(a, params, scratch_x, scratch_v, scratch_id, scratch_rho, scratch_vh, sent, pack_table):
        reals = sent.view(real)
        # [1] one invocation per row sent
        if a >= np.int64(pack_table[0, 1]):
            return
        # [2] its entry: the first whose rows (migrants, then halo) reach past it
        e = 0
        at = 0
        while a >= at + np.int64(pack_table[1 + 2 * e, 1]) + np.int64(pack_table[1 + 2 * e, 2]):
            at += np.int64(pack_table[1 + 2 * e, 1]) + np.int64(pack_table[1 + 2 * e, 2])
            e += 1
        migrants, halo = np.int64(pack_table[1 + 2 * e, 1]), np.int64(pack_table[1 + 2 * e, 2])
        # [3] the runs it goes in: the migrants', else past them the halo's; its slot
        j = a - at
        w = np.int64(pack_table[1 + 2 * e, 0])
        count = migrants
        migrant = j < migrants
        k = np.int64(pack_table[2 + 2 * e, 0]) + j
        if not migrant:
            w += migrant_words(migrants)
            j -= migrants
            count = halo
            k = np.int64(pack_table[2 + 2 * e, 1]) + j
        # [4] store
        for c in range(4):  # (a vec4)
            reals[(w + j * 4 * REAL_WORDS) // REAL_WORDS + c] = scratch_x[k, c]
        w += run_words(count, 4 * REAL_WORDS)
        for c in range(4):  # (a vec4)
            reals[(w + j * 4 * REAL_WORDS) // REAL_WORDS + c] = scratch_v[k, c]
        w += run_words(count, 4 * REAL_WORDS)
        reals[(w + j * REAL_WORDS) // REAL_WORDS] = scratch_rho[k]
        w += run_words(count, REAL_WORDS)
        sent[w + j] = scratch_id[k]
        w += run_words(count, 1)
        if VERLET and migrant:
            for c in range(4):  # (a vec4)
                reals[(w + j * 4 * REAL_WORDS) // REAL_WORDS + c] = scratch_vh[k, c]

    return launcher(pack_rows_main)
