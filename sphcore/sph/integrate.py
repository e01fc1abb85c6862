"""Symplectic Euler step, box walls and obstacles, one invocation per particle.

Mirror of shaders/sph/integrate.comp: same names, same statement order, same step labels.
A GLSL vec3 local `v` is `v_x, v_y, v_z` here.
"""
from functools import lru_cache

import numpy as np
from numba import njit

from sphcore.workgroups import launcher



@lru_cache(maxsize=None)
def integrate(spec, real=np.float32):
    DIM, WALLS, OBSTACLES = spec.DIM, spec.WALLS, spec.OBSTACLES

    @njit
    def integrate_main(i, params, particle_x, particle_v, particle_a, obstacle_box):
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
        # [4] obstacles (shaders/sph/obstacles.glsl): a particle that ended the step inside a box is put
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
        # [5] store
        particle_x[i, 0] = x_x
        particle_x[i, 1] = x_y
        particle_x[i, 2] = x_z
        particle_x[i, 3] = real(0.0)
        particle_v[i, 0] = v_x
        particle_v[i, 1] = v_y
        particle_v[i, 2] = v_z
        particle_v[i, 3] = real(0.0)

    return launcher(integrate_main)
