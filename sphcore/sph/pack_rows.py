"""After a step of a rank of sphcore.parallel whose rows go from GPU to GPU: the rows pick_rows packed into the
scratch buffers, written into `sent` as each other rank takes them, one invocation per row sent. The shader says more.

Mirror of shaders/sph/pack_rows.comp: same names, same statement order, same step labels. The words are written
through a view of the buffers' real type (every run starts on 16 bytes).
"""
from functools import lru_cache

import numpy as np
from numba import njit

from sphcore.sph.packed_rows import packed_rows, run_words
from sphcore.sph.pick_table import pick_table_functions
from sphcore.workgroups import launcher


@lru_cache(maxsize=None)
def pack_rows(spec, real=np.float32):
    VERLET = spec.VERLET
    REAL_WORDS = np.dtype(real).itemsize // 4
    migrant_words, halo_words = packed_rows(spec, real)
    table = pick_table_functions(spec)
    entry_rows, zone_of = table.entry_rows, table.zone_of

    @njit
    def pack_rows_main(a, params, scratch_x, scratch_v, scratch_id, scratch_rho, scratch_vh, sent, pick_table,
                       pick_count, layer_start):
        P = params[0]
        reals = sent.view(real)
        # [1] one invocation per row sent
        # [2] its entry: the first whose rows (migrants, then halo) reach past it; its first row sent and word in
        #     `sent`, its zones' first slot and their size; the words of every entry's rows
        entries = np.int64(pick_table[0, 0])
        e = entries
        at = w = slot = zone = rows = words = base = 0
        for f in range(entries):
            migrants = np.int64(pick_count[2 * f])
            halo = np.int64(pick_count[2 * f + 1])
            slots = zone_of(entry_rows(P, f, pick_table, layer_start)[1])
            if e == entries and a < rows + migrants + halo:
                e = f
                at = rows
                w = words
                slot = base
                zone = slots
            rows += migrants + halo
            words += migrant_words(migrants) + halo_words(halo)
            base += 2 * slots
        if e == entries or words > len(sent):
            return
        # [3] the runs it goes in: the migrants', else past them the halo's; its slot
        j = a - at
        count = np.int64(pick_count[2 * e])
        migrant = j < count
        k = slot + j
        if not migrant:
            w += migrant_words(count)
            j -= count
            count = np.int64(pick_count[2 * e + 1])
            k = slot + zone + j
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
