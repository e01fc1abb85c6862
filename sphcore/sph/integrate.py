"""Time step (integrators.py: symplectic Euler or the kick-drift-kick Verlet leapfrog), box walls and
obstacles, one invocation per particle. dt is P.dt, or with ADAPTIVE_DT the one choose_dt wrote into
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
from sphcore.sph.integrators import integrators
from sphcore.sph.shifting import shifting
from sphcore.workgroups import launcher



@lru_cache(maxsize=None)
def integrate(spec, real=np.float32):
    DIM, WALLS, OBSTACLES = spec.DIM, spec.WALLS, spec.OBSTACLES
    VERLET, ADAPTIVE_DT = spec.VERLET, spec.ADAPTIVE_DT
    drift_velocity = integrators(spec, real).drift_velocity
    stored_velocity = integrators(spec, real).stored_velocity
    moved_limit2 = skin(spec, real).moved_limit2
    LIST_SKIN = spec.LIST_SKIN
    SHIFTING, BODIES = spec.SHIFTING, spec.BODIES
    shift_of = shifting(spec, real).shift_of

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
        # [3] kick and drift (integrators.glsl): v is the velocity that moves the particle over the step
        a_x, a_y, a_z = particle_a[i, 0], particle_a[i, 1], particle_a[i, 2]
        v_x, v_y, v_z = drift_velocity(particle_v[i, 0], particle_v[i, 1], particle_v[i, 2], particle_vh[i, 0],
                                       particle_vh[i, 1], particle_vh[i, 2], a_x, a_y, a_z, dt, dt_prev)
        x_x = particle_x[i, 0] + dt * v_x
        x_y = particle_x[i, 1] + dt * v_y
        x_z = particle_x[i, 2] + dt * v_z
        if SHIFTING > 0:  # (shifting.glsl: Lind et al. 2012)
            s_x, s_y, s_z = shift_of(P, particle_shift[i, 0], particle_shift[i, 1], particle_shift[i, 2],
                                     particle_shift[i, 3], v_x, v_y, v_z, dt)
            x_x += s_x
            x_y += s_y
            x_z += s_z
        # [4] walls: each axis is tested on its own (no else-if), so a particle past a corner is
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
        # [5] obstacles (shaders/sph/obstacles.glsl): a particle that ended the step inside a box is put
        #     back onto the box's face nearest to it, its normal speed there treated as at a wall. The
        #     images across the faces keep particles off them; this catches the rare one that got in.
        for o in range(OBSTACLES):
            lo_x, lo_y, lo_z = real(obstacle_box[2 * o, 0]), real(obstacle_box[2 * o, 1]), real(obstacle_box[2 * o, 2])
            hi_x = real(obstacle_box[2 * o + 1, 0])
            hi_y = real(obstacle_box[2 * o + 1, 1])
            hi_z = real(obstacle_box[2 * o + 1, 2])
            depth_x = min(x_x - lo_x, hi_x - x_x)  # > 0: inside the box on that axis, that far from a face
            depth_y = min(x_y - lo_y, hi_y - x_y)
            depth_z = min(x_z - lo_z, hi_z - x_z)
            if depth_x <= real(0.0) or depth_y <= real(0.0) or (DIM == 3 and depth_z <= real(0.0)):
                continue
            if depth_x <= depth_y and (DIM == 2 or depth_x <= depth_z):
                lower = x_x - lo_x <= hi_x - x_x
                x_x = lo_x if lower else hi_x
                v_x = min(v_x, -P.restitution * v_x) if lower else max(v_x, -P.restitution * v_x)
            elif DIM == 2 or depth_y <= depth_z:
                lower = x_y - lo_y <= hi_y - x_y
                x_y = lo_y if lower else hi_y
                v_y = min(v_y, -P.restitution * v_y) if lower else max(v_y, -P.restitution * v_y)
            else:
                lower = x_z - lo_z <= hi_z - x_z
                x_z = lo_z if lower else hi_z
                v_z = min(v_z, -P.restitution * v_z) if lower else max(v_z, -P.restitution * v_z)
        # [6] store: the position, the velocity the integrator stores (integrators.glsl) and Verlet's half step's
        particle_x[i, 0] = x_x
        particle_x[i, 1] = x_y
        particle_x[i, 2] = x_z
        particle_x[i, 3] = real(0.0)
        s_x, s_y, s_z = stored_velocity(v_x, v_y, v_z, a_x, a_y, a_z, dt)
        particle_v[i, 0] = s_x
        particle_v[i, 1] = s_y
        particle_v[i, 2] = s_z
        particle_v[i, 3] = real(0.0)
        if VERLET:
            particle_vh[i, 0] = v_x
            particle_vh[i, 1] = v_y
            particle_vh[i, 2] = v_z
            particle_vh[i, 3] = real(0.0)
        # [7] reused lists: the next step builds them where this particle has moved too far since the last build
        #     (every particle that has writes the same 1)
        if LIST_SKIN > 0:
            moved_x = x_x - scratch_x[i, 0]
            moved_y = x_y - scratch_x[i, 1]
            moved_z = x_z - scratch_x[i, 2]
            if moved_x * moved_x + moved_y * moved_y + moved_z * moved_z > moved_limit2(P):
                control[CONTROL_REBUILD] = 1
    return launcher(integrate_main)
