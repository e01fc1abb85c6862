"""Time integrators, chosen by the closure constant VERLET (scene key time.integrator).

Mirror of shaders/sph/integrators.glsl: same names, same statements (the schemes, what each
stores and what is second order are described there). symplectic_euler: v += dt a, x += dt v;
verlet: the kick-drift-kick leapfrog with one force evaluation per step, the half-step velocity
kept in particle_vh and the predicted end velocity in particle_v. `dt` and `dt_prev` are float32
(the parameter block's, or time_state's); a GLSL vec3 `v` is `v_x, v_y, v_z`.
"""
from functools import lru_cache

import numpy as np
from numba import njit
from sphcore.sph import named

INTEGRATORS = ("symplectic_euler", "verlet")  # scene key time.integrator -> VERLET (index)

f32 = np.float32


@lru_cache(maxsize=None)
def integrators(spec, real=np.float32):
    VERLET = spec.VERLET

    @njit
    def symplectic_euler_kick(v_x, v_y, v_z, a_x, a_y, a_z, dt):
        """Symplectic Euler's velocity over the step: v_{n+1} = v_n + dt a_n."""
        return v_x + dt * a_x, v_y + dt * a_y, v_z + dt * a_z

    @njit
    def verlet_kick(v_x, v_y, v_z, vh_x, vh_y, vh_z, a_x, a_y, a_z, dt, dt_prev):
        """Verlet's v_{n+1/2}: the last step's closing half kick (none at the first, dt_prev = 0),
        then this step's opening one."""
        vn_x, vn_y, vn_z = v_x, v_y, v_z
        if dt_prev > f32(0.0):
            vn_x = vh_x + (f32(0.5) * dt_prev) * a_x
            vn_y = vh_y + (f32(0.5) * dt_prev) * a_y
            vn_z = vh_z + (f32(0.5) * dt_prev) * a_z
        return vn_x + (f32(0.5) * dt) * a_x, vn_y + (f32(0.5) * dt) * a_y, vn_z + (f32(0.5) * dt) * a_z

    @njit
    def drift_velocity(v_x, v_y, v_z, vh_x, vh_y, vh_z, a_x, a_y, a_z, dt, dt_prev):
        """The velocity that moves the particle over the step."""
        if VERLET:
            return verlet_kick(v_x, v_y, v_z, vh_x, vh_y, vh_z, a_x, a_y, a_z, dt, dt_prev)
        return symplectic_euler_kick(v_x, v_y, v_z, a_x, a_y, a_z, dt)

    @njit
    def stored_velocity(v_x, v_y, v_z, a_x, a_y, a_z, dt):
        """The velocity stored in particle_v at the step's end, from the drift velocity (after the walls)."""
        if VERLET:
            return v_x + (f32(0.5) * dt) * a_x, v_y + (f32(0.5) * dt) * a_y, v_z + (f32(0.5) * dt) * a_z
        return v_x, v_y, v_z

    return named(symplectic_euler_kick, verlet_kick, drift_velocity, stored_velocity)
