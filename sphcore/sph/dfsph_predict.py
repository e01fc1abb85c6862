"""DFSPH: the velocity v* = v + dt a that the constant-density solve corrects, one invocation per particle,
once this step's dt is known and before the solve's first residual; kept in scratch_v (free after the
sort), where dfsph_residual reads it and dfsph_velocity updates it.

Mirror of shaders/sph/dfsph_predict.comp: same names, same statement order, same step labels.
"""
from functools import lru_cache

import numpy as np
from numba import njit

from sphcore.workgroups import launcher


@lru_cache(maxsize=None)
def dfsph_predict(spec, real=np.float32):

    @njit
    def dfsph_predict_main(i, params, particle_v, particle_a, particle_vstar, time_state):
        P = params[0]
        # [1] one invocation per particle
        if i >= P.n:
            return
        # [2] v* = v + dt a with this step's dt
        dt = real(time_state[0, 0])
        particle_vstar[i, 0] = particle_v[i, 0] + dt * particle_a[i, 0]
        particle_vstar[i, 1] = particle_v[i, 1] + dt * particle_a[i, 1]
        particle_vstar[i, 2] = particle_v[i, 2] + dt * particle_a[i, 2]
        particle_vstar[i, 3] = real(0.0)

    return launcher(dfsph_predict_main)
