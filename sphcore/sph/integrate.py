"""Symplectic Euler step and box walls, one invocation per particle.

Mirror of shaders/sph/integrate.comp: same names, same statement order, same step labels.
A GLSL vec3 local `v` is `v_x, v_y, v_z` here.
"""
from functools import lru_cache

import numpy as np
from numba import njit

from sphcore.workgroups import launcher



@lru_cache(maxsize=None)
def integrate(spec, real=np.float32):
    DIM, WALLS = spec.DIM, spec.WALLS

    @njit
    def integrate_main(i, params, particle_x, particle_v, particle_a):
        P = params[0]
        # [1] one invocation per particle; the grid is rounded up to whole work groups
        if i >= P.n:
            return
        # [2] symplectic Euler: v += dt a, then x += dt v
        v_x = particle_v[i, 0] + P.dt * particle_a[i, 0]
        v_y = particle_v[i, 1] + P.dt * particle_a[i, 1]
        v_z = particle_v[i, 2] + P.dt * particle_a[i, 2]
        x_x = particle_x[i, 0] + P.dt * v_x
        x_y = particle_x[i, 1] + P.dt * v_y
        x_z = particle_x[i, 2] + P.dt * v_z
        # [3] walls: each axis is tested on its own (no else-if), so a particle past a corner is
        #     put back on every wall it crossed in the same step. Clamp the position; an outward
        #     normal speed is reversed and scaled by the restitution, an inward one is kept.
        if WALLS:
            if x_x < P.box_min[0]:
                x_x = P.box_min[0]
                v_x = max(v_x, -P.restitution * v_x)
            if x_x > P.box_max[0]:
                x_x = P.box_max[0]
                v_x = min(v_x, -P.restitution * v_x)
            if x_y < P.box_min[1]:
                x_y = P.box_min[1]
                v_y = max(v_y, -P.restitution * v_y)
            if x_y > P.box_max[1]:
                x_y = P.box_max[1]
                v_y = min(v_y, -P.restitution * v_y)
            if DIM == 3 and x_z < P.box_min[2]:
                x_z = P.box_min[2]
                v_z = max(v_z, -P.restitution * v_z)
            if DIM == 3 and x_z > P.box_max[2]:
                x_z = P.box_max[2]
                v_z = min(v_z, -P.restitution * v_z)
        # [4] store
        particle_x[i, 0] = x_x
        particle_x[i, 1] = x_y
        particle_x[i, 2] = x_z
        particle_x[i, 3] = real(0.0)
        particle_v[i, 0] = v_x
        particle_v[i, 1] = v_y
        particle_v[i, 2] = v_z
        particle_v[i, 3] = real(0.0)

    return launcher(integrate_main)
