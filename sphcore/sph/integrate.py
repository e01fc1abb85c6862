"""Time step (integrate_row.py: integrators.py's symplectic Euler or kick-drift-kick Verlet leapfrog, box walls and
obstacles), one invocation per particle. dt is P.dt, or with ADAPTIVE_DT the one choose_dt wrote into
time_state this step. Reused lists (LIST_SKIN): a particle that has moved too far from where it was at the
lists' build asks for the next build (cells.glsl: moved_limit2). With shifting (SHIFTING) the drift is followed
by the particle's shift (shifting.py), before the walls.

Mirror of shaders/sph/integrate.comp: same names, same statement order, same step labels.
A GLSL vec3 local `v` is `v_x, v_y, v_z` here.
"""
from functools import lru_cache

import numpy as np
from numba import njit

from sphcore.sph.cells import skin
from sphcore.sph.dfsph import CONTROL_REBUILD
from sphcore.sph.integrate_row import integrate_row
from sphcore.workgroups import launcher



@lru_cache(maxsize=None)
def integrate(spec, real=np.float32):
    VERLET, ADAPTIVE_DT, LIST_SKIN, BODIES = spec.VERLET, spec.ADAPTIVE_DT, spec.LIST_SKIN, spec.BODIES
    integrated = integrate_row(spec, real)
    moved_limit2 = skin(spec, real).moved_limit2

    @njit
    def integrate_main(i, params, particle_x, particle_v, particle_a, scratch_x, obstacle_box, particle_vh, time_state,
                       control, particle_shift, particle_id):
        P = params[0]
        # [1] one invocation per fluid particle; the grid is rounded up to whole work groups
        if i >= P.n or (BODIES and particle_id[i] >= P.fluid_count):
            return
        # [2] the step's dt: P.dt, or the device's (time_state: dt, the last step's dt, time; choose_dt.comp)
        dt = time_state[0, 0] if ADAPTIVE_DT else P.dt
        dt_prev = time_state[0, 1] if VERLET else np.float32(0.0)
        # [3] the step (integrate_row.glsl), stored: the position, the velocity the integrator stores and Verlet's half
        #     step's
        (x_x, x_y, x_z), (v_x, v_y, v_z), (vh_x, vh_y, vh_z) = integrated(
            P, i, dt, dt_prev, particle_shift[i], particle_x, particle_v, particle_a, particle_vh, obstacle_box)
        particle_x[i, 0] = x_x
        particle_x[i, 1] = x_y
        particle_x[i, 2] = x_z
        particle_x[i, 3] = real(0.0)
        particle_v[i, 0] = v_x
        particle_v[i, 1] = v_y
        particle_v[i, 2] = v_z
        particle_v[i, 3] = real(0.0)
        if VERLET:
            particle_vh[i, 0] = vh_x
            particle_vh[i, 1] = vh_y
            particle_vh[i, 2] = vh_z
            particle_vh[i, 3] = real(0.0)
        # [4] reused lists: the next step builds them where this particle has moved too far since the last build
        #     (every particle that has writes the same 1)
        if LIST_SKIN > 0:
            moved_x = x_x - scratch_x[i, 0]
            moved_y = x_y - scratch_x[i, 1]
            moved_z = x_z - scratch_x[i, 2]
            if moved_x * moved_x + moved_y * moved_y + moved_z * moved_z > moved_limit2(P):
                control[CONTROL_REBUILD] = 1
    return launcher(integrate_main)
