"""Adaptive time step, first of two stages: each work group's largest |v|^2 and |a|^2, reduced in
shared memory to one partial per group (dt_partial); choose_dt reduces the partials.

Mirror of shaders/sph/reduce_dt.comp: same names, same statement order, same step labels. The
shader's barriers split it into phases, so this mirror is launched by its own `launch`, not by
sphcore.workgroups.launcher: per work group (groups in parallel, prange), one local loop over the
invocations per phase between barriers, with the group's shared arrays as scratch (STYLE.md). A
maximum is exact in any order: the partials are those of any GPU schedule. On a rank of sphcore.parallel
the particles of its slab only (P.owned_first, owned_end: the others' are a halo).
"""
from functools import lru_cache

import numpy as np
from numba import njit, prange

from sphcore.numba_cache import cached


@lru_cache(maxsize=None)
def reduce_dt(spec, real=np.float32):
    BODIES = spec.BODIES

    @njit
    def reduce_dt_load(i, lid, params, particle_v, particle_a, particle_id, cell_start, s_v2, s_a2):
        P = params[0]
        # [1] own |v|^2 and |a|^2; an invocation past the last particle, or on a rank past the rows the sort gave
        #     its slab's cells, holds 0 (all reach the barriers)
        first = 0
        end = P.n
        if P.owned_end > 0:
            first = cell_start[P.owned_first]
            end = cell_start[P.owned_end] if P.owned_end < P.cell_total else P.n
        v2 = real(0.0)
        a2 = real(0.0)
        if i >= first and i < end and not (BODIES and particle_id[i] >= P.fluid_count):
            v2 = particle_v[i, 0] * particle_v[i, 0] + particle_v[i, 1] * particle_v[i, 1] + particle_v[i, 2] * particle_v[i, 2]
            a2 = particle_a[i, 0] * particle_a[i, 0] + particle_a[i, 1] * particle_a[i, 1] + particle_a[i, 2] * particle_a[i, 2]
        s_v2[lid] = v2
        s_a2[lid] = a2

    @njit(parallel=True, error_model="numpy")
    def launch(n_groups, local_size, params, particle_v, particle_a, dt_partial, particle_id, cell_start):
        for group in prange(n_groups):
            s_v2 = np.empty(local_size, real)  # the group's shared memory
            s_a2 = np.empty(local_size, real)
            for lid in range(local_size):
                reduce_dt_load(group * local_size + lid, lid, params, particle_v, particle_a, particle_id, cell_start,
                               s_v2, s_a2)
            # (barrier)
            # [2] tree: at stride s, each invocation at a multiple of 2 s takes the larger of its own and the one s above
            stride = 1
            while stride < local_size:
                for lid in range(local_size):
                    if lid % (2 * stride) == 0 and lid + stride < local_size:
                        s_v2[lid] = max(s_v2[lid], s_v2[lid + stride])
                        s_a2[lid] = max(s_a2[lid], s_a2[lid + stride])
                # (barrier)
                stride *= 2
            # [3] the group's partial
            dt_partial[group, 0] = s_v2[0]
            dt_partial[group, 1] = s_a2[0]

    return cached(launch)
