"""On a rank of sphcore.parallel, after the step's sort: the rows its pick reads into band_rows, and their count in
work groups into rank_groups[0] (x, 1, 1, the rows), which the indirect dispatches of compute_forces' first pass,
pick_rows and pack_rows read. One invocation; the shader says more.

Mirror of shaders/sph/pick_groups.comp: same names, same statement order, same step labels. It has its own `launch`,
which passes the work groups' size (gl_WorkGroupSize.x).
"""
from functools import lru_cache

import numpy as np
from numba import njit

from sphcore.numba_cache import cached
from sphcore.sph.pick_table import pick_table_functions


@lru_cache(maxsize=None)
def pick_groups(spec, real=np.float32):
    entry_rows = pick_table_functions(spec).entry_rows

    @njit
    def pick_groups_main(i, local_size, params, pick_table, layer_start, band_rows, rank_groups):
        P = params[0]
        # [1] one invocation
        if i != 0:
            return
        # [2] each entry's rows, and their count
        entries = np.int64(pick_table[0, 0])
        rows = 0
        band_rows[0, 0] = entries
        band_rows[0, 1] = 0
        for e in range(entries):
            first, count = entry_rows(P, e, pick_table, layer_start)
            band_rows[1 + e, 0] = first
            band_rows[1 + e, 1] = count
            rows += count
        # [3] the dispatch of one invocation a row
        rank_groups[0, 0] = (rows + local_size - 1) // local_size
        rank_groups[0, 1] = 1
        rank_groups[0, 2] = 1
        rank_groups[0, 3] = rows

    @njit
    def launch(n_groups, local_size, params, pick_table, layer_start, band_rows, rank_groups):
        for group in range(n_groups):
            for lid in range(local_size):
                pick_groups_main(group * local_size + lid, local_size, params, pick_table, layer_start, band_rows,
                                 rank_groups)

    return cached(launch)
