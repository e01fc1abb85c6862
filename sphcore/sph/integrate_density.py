"""Continuity density: rho_n = rho_{n-1} + dt_{n-1} drho(x_n, v_n) and its pressure, one invocation
per particle, between compute_density and compute_forces (in the plan with physics.density =
"continuity" only; why the density is advanced here, with the new velocities: see the shader).

Mirror of shaders/sph/integrate_density.comp: same names, same statement order, same step labels.
"""
from functools import lru_cache

import numpy as np
from numba import njit

from sphcore.sph.equation_of_state import equation_of_state
from sphcore.workgroups import launcher


@lru_cache(maxsize=None)
def integrate_density(spec, real=np.float32):
    ADAPTIVE_DT = spec.ADAPTIVE_DT
    equation_of_state_ = equation_of_state(spec, real)

    @njit
    def integrate_density_main(i, params, particle_rho, particle_p, particle_drho, time_state):
        P = params[0]
        # [1] one invocation per particle; the grid is rounded up to whole work groups
        if i >= P.n:
            return
        # [2] the last step's dt
        dt = time_state[0, 0] if ADAPTIVE_DT else P.dt
        # [3] rho_n = rho_{n-1} + dt drho, and its pressure
        rho = particle_rho[i] + dt * particle_drho[i]
        p = equation_of_state_(P, rho)
        # [4] store
        particle_rho[i] = rho
        particle_p[i] = p

    return launcher(integrate_density_main)
