"""Put each particle's index at its cell's start plus its slot: a counting sort by cell.
One invocation per particle.

Mirror of shaders/sph/scatter_particles.comp: same names, same statement order, same step labels.
"""
from functools import lru_cache

import numpy as np
from numba import njit

from sphcore.workgroups import launcher


@lru_cache(maxsize=None)
def scatter_particles(spec, real=np.float32):
    @njit
    def scatter_particles_main(i, params, particle_cell, particle_slot, cell_start, sorted_index):
        P = params[0]
        # [1] one invocation per particle
        if i >= P.n:
            return
        # [2] slots of one cell are distinct and below its count, so every position is written once
        sorted_index[cell_start[particle_cell[i]] + particle_slot[i]] = i

    return launcher(scatter_particles_main)
