"""Copy the sorted position, velocity and id (and with CONTINUITY the density) back into the particle
buffers: from here on in the step, particles of one cell are contiguous (cell c holds
cell_start[c] .. + count).
One invocation per particle.

Mirror of shaders/sph/apply_order.comp: same names, same statement order, same step labels.
"""
from functools import lru_cache

import numpy as np
from numba import njit

from sphcore.workgroups import launcher


@lru_cache(maxsize=None)
def apply_order(spec, real=np.float32):
    CONTINUITY, VERLET = spec.CONTINUITY, spec.VERLET
    DFSPH = spec.DFSPH

    @njit
    def apply_order_main(k, params, particle_x, particle_v, particle_id, scratch_x, scratch_v, scratch_id,
                         particle_rho, scratch_rho, particle_a, particle_vh,
                         particle_kappa):
        P = params[0]
        # [1] one invocation per particle
        if k >= P.n:
            return
        # [2] copy back
        for c in range(4):  # (a vec4)
            particle_x[k, c] = scratch_x[k, c]
        for c in range(4):  # (a vec4)
            particle_v[k, c] = scratch_v[k, c]
        particle_id[k] = scratch_id[k]
        if CONTINUITY:
            particle_rho[k] = scratch_rho[k]
        # [3] Verlet's half-step velocity, back from its scratch (gather_particles.comp)
        if VERLET:
            for c in range(4):  # (a vec4)
                particle_vh[k, c] = particle_a[k, c]
        # [4] DFSPH's warm start, back from its scratch (gather_particles.comp)
        if DFSPH:
            particle_kappa[k] = scratch_rho[k]

    return launcher(apply_order_main)
