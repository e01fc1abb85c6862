"""The pick's table on a rank of sphcore.parallel: the entries (another rank each), the layers whose rows each may
need, the rows the step's sort gave them (layer_start), the zones of slots each takes. The shader says more.

Mirror of shaders/sph/pick_table.glsl: same names, same statements (the buffers passed in).
"""
from collections import namedtuple
from functools import lru_cache

import numpy as np
from numba import njit

PICK_ALIGN = 4  # rows: 16 bytes of a 4-byte buffer

PickTable = namedtuple("PickTable", "row_of entry_rows zone_of")


@lru_cache(maxsize=None)
def pick_table_functions(spec):
    AXIS = spec.DIM - 1

    @njit
    def row_of(P, layer, pick_table, layer_start):
        """The first row the step's sort gave layer `layer` (the rows held past the last layer)."""
        return np.int64(layer_start[layer]) if layer < np.int64(P.grid_dim[AXIS]) else np.int64(pick_table[0, 1])

    @njit
    def entry_rows(P, e, pick_table, layer_start):
        """Entry e's rows: the first, and how many."""
        first = row_of(P, np.int64(pick_table[1 + e, 0]), pick_table, layer_start)
        return first, row_of(P, np.int64(pick_table[1 + e, 1]), pick_table, layer_start) - first

    @njit
    def zone_of(rows):
        """The slots of each of an entry's two zones (migrants, halo): its rows rounded up to PICK_ALIGN."""
        return (rows + PICK_ALIGN - 1) // PICK_ALIGN * PICK_ALIGN

    return PickTable(row_of, entry_rows, zone_of)
