"""The step's dt and the simulated time, on the device, one work group: time_state[0] = (dt, the
last step's dt, time hi, time lo). ADAPTIVE_DT: dt = min(P.dt, cfl_number h / (c + |v|max),
cfl_number sqrt(h / |a|max)) over reduce_dt's partials, which the group's invocations share and
reduce in shared memory; else P.dt. The time is summed in a compensated float32 pair (Kahan 1965).
On a rank of sphcore.parallel, level 1 first writes the largest as the first partial (the shader says more).

Mirror of shaders/sph/choose_dt.comp: same names, same statement order, same step labels. The
shader's barriers split it into phases, so this mirror has its own `launch` (one group is
dispatched): one local loop over the invocations per phase, the shared arrays as scratch. The
float32 arithmetic of the time is numpy's, in order, as the shader's `precise` variables keep it.
"""
from functools import lru_cache

import numpy as np
from numba import njit

from sphcore.numba_cache import cached

f32 = np.float32


@lru_cache(maxsize=None)
def choose_dt(spec, real=np.float32):
    ADAPTIVE_DT, TAIT = spec.ADAPTIVE_DT, spec.TAIT
    DFSPH = spec.DFSPH

    @njit
    def choose_dt_load(lid, local_size, params, dt_partial, s_v2, s_a2):
        P = params[0]
        # [1] the largest |v|^2 and |a|^2 of every local_size-th of reduce_dt's partials (one per work group
        #     of its dispatch), from this invocation's on; one work group is dispatched
        groups = (int(P.n) + local_size - 1) // local_size
        v2 = real(0.0)
        a2 = real(0.0)
        if ADAPTIVE_DT:
            for g in range(lid, groups, local_size):
                v2 = max(v2, dt_partial[g, 0])
                a2 = max(a2, dt_partial[g, 1])
        s_v2[lid] = v2
        s_a2[lid] = a2

    @njit
    def choose_dt_tree(local_size, s_v2, s_a2):
        # [2] tree: at stride s, each invocation at a multiple of 2 s takes the larger of its own and the one s above
        stride = 1
        while stride < local_size:
            for lid in range(local_size):
                if lid % (2 * stride) == 0 and lid + stride < local_size:
                    s_v2[lid] = max(s_v2[lid], s_v2[lid + stride])
                    s_a2[lid] = max(s_a2[lid], s_a2[lid + stride])
            # (barrier)
            stride *= 2

    @njit
    def choose_dt_last(params, time_state, dt_partial, s_v2, s_a2):
        P = params[0]
        # (P.level 1, a rank's: the largest as the first partial, where the host takes the largest over the ranks)
        if P.level == 1:
            dt_partial[0, 0] = s_v2[0]
            dt_partial[0, 1] = s_a2[0]
            return
        dt = P.dt
        if ADAPTIVE_DT:
            # [3] the bounds: CFL on c + |v|max, force on |a|max (none where nothing accelerates), P.dt
            v2 = s_v2[0]
            a2 = s_a2[0]
            c = np.sqrt(real(7.0) * P.stiffness / P.rest_density if TAIT else real(P.stiffness))
            bound = P.cfl_number * P.h / (c + np.sqrt(v2))
            # (DFSPH, incompressible: the CFL on the particle speed alone, cfl_number = time.cfl_number dx / h)
            if DFSPH:
                bound = P.cfl_number * P.h / np.sqrt(v2) if np.sqrt(v2) * real(P.dt) > P.cfl_number * P.h else real(P.dt)
            if a2 > real(0.0):
                bound = min(bound, P.cfl_number * np.sqrt(P.h / np.sqrt(a2)))
            dt = min(P.dt, f32(bound))
        # [4] the time, t += dt, summed in a compensated float32 pair (Kahan 1965)
        y = dt + time_state[0, 3]
        t = time_state[0, 2] + y
        lo = y - (t - time_state[0, 2])
        # [5] store: this step's dt, the last step's, the time
        time_state[0, 1] = time_state[0, 0]
        time_state[0, 0] = dt
        time_state[0, 2] = t
        time_state[0, 3] = lo

    @njit(error_model="numpy")
    def launch(n_groups, local_size, params, time_state, dt_partial):
        for group in range(n_groups):  # one
            s_v2 = np.empty(local_size, real)  # the group's shared memory
            s_a2 = np.empty(local_size, real)
            for lid in range(local_size):
                choose_dt_load(lid, local_size, params, dt_partial, s_v2, s_a2)
            # (barrier)
            choose_dt_tree(local_size, s_v2, s_a2)
            # invocation 0 only
            choose_dt_last(params, time_state, dt_partial, s_v2, s_a2)

    return cached(launch)
