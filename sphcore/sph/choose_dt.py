"""The step's dt and the simulated time, on the device, one invocation: time_state[0] = (dt, the
last step's dt, time hi, time lo). ADAPTIVE_DT: dt = min(P.dt, cfl_number h / (c + |v|max),
cfl_number sqrt(h / |a|max)) over reduce_dt's partials; else P.dt. The time is summed in a
compensated float32 pair (Kahan 1965).

Mirror of shaders/sph/choose_dt.comp: same names, same statement order, same step labels. Its
`launch` passes the work-group size, which the shader reads as gl_WorkGroupSize.x (the number of
reduce_dt's partials depends on it). The float32 arithmetic of the time is numpy's, in order, as
the shader's `precise` variables keep it.
"""
from functools import lru_cache

import numpy as np
from numba import njit

f32 = np.float32


@lru_cache(maxsize=None)
def choose_dt(spec, real=np.float32):
    ADAPTIVE_DT, TAIT = spec.ADAPTIVE_DT, spec.TAIT

    @njit
    def choose_dt_main(gid, local_size, params, time_state, dt_partial):
        P = params[0]
        # [1] one invocation
        if gid != 0:
            return
        dt = P.dt
        if ADAPTIVE_DT:
            # [2] the largest |v|^2 and |a|^2 over reduce_dt's partials, one per work group of its dispatch
            groups = (int(P.n) + local_size - 1) // local_size
            v2 = real(0.0)
            a2 = real(0.0)
            for g in range(groups):
                v2 = max(v2, dt_partial[g, 0])
                a2 = max(a2, dt_partial[g, 1])
            # [3] the bounds: CFL on c + |v|max, force on |a|max (none where nothing accelerates), P.dt
            c = np.sqrt(real(7.0) * P.stiffness / P.rest_density if TAIT else real(P.stiffness))
            bound = P.cfl_number * P.h / (c + np.sqrt(v2))
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
        for group in range(n_groups):
            for lid in range(local_size):
                choose_dt_main(group * local_size + lid, local_size, params, time_state, dt_partial)

    return launch
