"""A particle's step (integrators.py: symplectic Euler or the kick-drift-kick Verlet leapfrog), box walls and
obstacles: what integrate stores of row i, also what pick_rows sends of the rows it picks before integrate has run.
The shader says more.

Mirror of shaders/sph/integrate_row.glsl: same names, same statement order, same step labels.
A GLSL vec3 local `v` is `v_x, v_y, v_z` here; the out parameters are returned.
"""
from functools import lru_cache

import numpy as np
from numba import njit

from sphcore.sph.integrators import integrators
from sphcore.sph.shifting import shifting


@lru_cache(maxsize=None)
def integrate_row(spec, real=np.float32):
    DIM, WALLS, OBSTACLES, SHIFTING = spec.DIM, spec.WALLS, spec.OBSTACLES, spec.SHIFTING
    drift_velocity = integrators(spec, real).drift_velocity
    stored_velocity = integrators(spec, real).stored_velocity
    shift_of = shifting(spec, real).shift_of

    @njit
    def integrated(P, i, dt, dt_prev, shift, particle_x, particle_v, particle_a, particle_vh, obstacle_box):
        """Row i after a step of `dt` (the last step's `dt_prev`: Verlet) and, with shifting, `shift`'s sums: its
        position x, the velocity the integrator stores v and the one that moved it vh, as (x, y, z) each."""
        # [1] kick and drift (integrators.glsl): vh is the velocity that moves the particle over the step
        a_x, a_y, a_z = particle_a[i, 0], particle_a[i, 1], particle_a[i, 2]
        vh_x, vh_y, vh_z = drift_velocity(particle_v[i, 0], particle_v[i, 1], particle_v[i, 2], particle_vh[i, 0],
                                          particle_vh[i, 1], particle_vh[i, 2], a_x, a_y, a_z, dt, dt_prev)
        x_x = particle_x[i, 0] + dt * vh_x
        x_y = particle_x[i, 1] + dt * vh_y
        x_z = particle_x[i, 2] + dt * vh_z
        if SHIFTING > 0:  # (shifting.glsl: Lind et al. 2012)
            s_x, s_y, s_z = shift_of(P, shift[0], shift[1], shift[2], shift[3], vh_x, vh_y, vh_z, dt)
            x_x += s_x
            x_y += s_y
            x_z += s_z
        # [2] walls: each axis is tested on its own (no else-if), so a particle past a corner is
        #     put back on every wall it crossed in the same step. Clamp the position; an outward
        #     normal speed is reversed and scaled by the restitution, an inward one is kept.
        if WALLS:
            if x_x < P.box_min[0]:
                x_x = P.box_min[0]
                vh_x = max(vh_x, -P.restitution * vh_x)
            if x_x > P.box_max[0]:
                x_x = P.box_max[0]
                vh_x = min(vh_x, -P.restitution * vh_x)
            if x_y < P.box_min[1]:
                x_y = P.box_min[1]
                vh_y = max(vh_y, -P.restitution * vh_y)
            if x_y > P.box_max[1]:
                x_y = P.box_max[1]
                vh_y = min(vh_y, -P.restitution * vh_y)
            if DIM == 3 and x_z < P.box_min[2]:
                x_z = P.box_min[2]
                vh_z = max(vh_z, -P.restitution * vh_z)
            if DIM == 3 and x_z > P.box_max[2]:
                x_z = P.box_max[2]
                vh_z = min(vh_z, -P.restitution * vh_z)
        # [3] obstacles (shaders/sph/obstacles.glsl): a particle that ended the step inside a box is put
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
                vh_x = min(vh_x, -P.restitution * vh_x) if lower else max(vh_x, -P.restitution * vh_x)
            elif DIM == 2 or depth_y <= depth_z:
                lower = x_y - lo_y <= hi_y - x_y
                x_y = lo_y if lower else hi_y
                vh_y = min(vh_y, -P.restitution * vh_y) if lower else max(vh_y, -P.restitution * vh_y)
            else:
                lower = x_z - lo_z <= hi_z - x_z
                x_z = lo_z if lower else hi_z
                vh_z = min(vh_z, -P.restitution * vh_z) if lower else max(vh_z, -P.restitution * vh_z)
        # [4] the velocity the integrator stores (integrators.glsl)
        v = stored_velocity(vh_x, vh_y, vh_z, a_x, a_y, a_z, dt)
        return (x_x, x_y, x_z), v, (vh_x, vh_y, vh_z)

    return integrated
