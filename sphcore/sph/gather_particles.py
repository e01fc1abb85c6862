"""Copy position, velocity and id into sorted order (scratch buffers); apply_order copies them
back. With continuity density (CONTINUITY) the density is state and travels too. One invocation
per sorted position.

Mirror of shaders/sph/gather_particles.comp: same names, same statement order, same step labels.
"""
from functools import lru_cache

import numpy as np
from numba import njit

from sphcore.workgroups import launcher


@lru_cache(maxsize=None)
def gather_particles(spec, real=np.float32):
    CONTINUITY, VERLET = spec.CONTINUITY, spec.VERLET
    DFSPH = spec.DFSPH

    @njit
    def gather_particles_main(k, params, particle_x, particle_v, particle_id, sorted_index,
                              scratch_x, scratch_v, scratch_id, particle_rho, scratch_rho, particle_a, particle_vh,
                              particle_kappa):
        P = params[0]
        # [1] one invocation per sorted position
        if k >= P.n:
            return
        # [2] fetch the particle that goes there
        j = sorted_index[k]
        for c in range(4):  # (a vec4)
            scratch_x[k, c] = particle_x[j, c]
        for c in range(4):  # (a vec4)
            scratch_v[k, c] = particle_v[j, c]
        scratch_id[k] = particle_id[j]
        if CONTINUITY:
            scratch_rho[k] = particle_rho[j]
        # [3] Verlet's half-step velocity (integrators.glsl) travels too, with particle_a as its scratch:
        #     nothing reads the acceleration before compute_forces rewrites it
        if VERLET:
            for c in range(4):  # (a vec4)
                particle_a[k, c] = particle_vh[j, c]
        # [4] DFSPH's warm start (dfsph.glsl) travels too, with scratch_rho as its scratch (no continuity density)
        if DFSPH:
            scratch_rho[k] = particle_kappa[j]

    return launcher(gather_particles_main)
