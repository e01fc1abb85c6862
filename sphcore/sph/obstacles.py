"""Box obstacles (scene key domain.obstacles): the faces of the boxes as mirror planes.

Mirror of shaders/sph/obstacles.glsl: same names, same statements (the reasons are there). GLSL
reads the parameter block `P` and the buffer `obstacle_box` as globals; here they are arguments.
A GLSL vec3 `v` is `v_x, v_y, v_z`; `real` is the shader's `real` (shaders/sph/real.glsl).
"""
from functools import lru_cache

import numpy as np
from numba import njit
from sphcore.sph import named
from sphcore.sph.cells import cells, skin


@lru_cache(maxsize=None)
def obstacles(spec, real=np.float32):
    DIM, OBSTACLES, LIST_SKIN = spec.DIM, spec.OBSTACLES, spec.LIST_SKIN
    near_walls = cells(spec, real).near_walls
    near_walls_within = skin(spec, real).near_walls_within
    list_reach = skin(spec, real).list_reach

    @njit
    def near_obstacles(P, obstacle_box, x_x, x_y, x_z, mirrored, wall_x, wall_y, wall_z):
        """(mirrored, wall, inward): on each axis where x lies in front of an obstacle face (outside
        the box on that axis by less than h, within it on the others) nearer than that axis's
        mirrored wall, the face becomes the axis's mirror plane; inward points into the fluid."""
        inward_x = real(1.0) if wall_x == P.box_min[0] else real(-1.0)
        inward_y = real(1.0) if wall_y == P.box_min[1] else real(-1.0)
        inward_z = real(1.0) if wall_z == P.box_min[2] else real(-1.0)
        for o in range(OBSTACLES):
            lo_x, lo_y, lo_z = real(obstacle_box[2 * o, 0]), real(obstacle_box[2 * o, 1]), real(obstacle_box[2 * o, 2])
            hi_x = real(obstacle_box[2 * o + 1, 0])
            hi_y = real(obstacle_box[2 * o + 1, 1])
            hi_z = real(obstacle_box[2 * o + 1, 2])
            gap_x = max(lo_x - x_x, x_x - hi_x)  # > 0: outside the box on that axis, by that much
            gap_y = max(lo_y - x_y, x_y - hi_y)
            gap_z = max(lo_z - x_z, x_z - hi_z)
            if DIM == 2:
                gap_z = real(0.0)
            if (gap_x >= real(0.0) and gap_x < P.h and gap_y <= real(0.0) and gap_z <= real(0.0)
                    and ((mirrored & 1) == 0 or gap_x < abs(x_x - wall_x))):
                wall_x = lo_x if x_x <= lo_x else hi_x
                inward_x = real(-1.0) if x_x <= lo_x else real(1.0)
                mirrored |= 1
            if (gap_y >= real(0.0) and gap_y < P.h and gap_x <= real(0.0) and gap_z <= real(0.0)
                    and ((mirrored & 2) == 0 or gap_y < abs(x_y - wall_y))):
                wall_y = lo_y if x_y <= lo_y else hi_y
                inward_y = real(-1.0) if x_y <= lo_y else real(1.0)
                mirrored |= 2
            if (DIM == 3 and gap_z >= real(0.0) and gap_z < P.h and gap_x <= real(0.0) and gap_y <= real(0.0)
                    and ((mirrored & 4) == 0 or gap_z < abs(x_z - wall_z))):
                wall_z = lo_z if x_z <= lo_z else hi_z
                inward_z = real(-1.0) if x_z <= lo_z else real(1.0)
                mirrored |= 4
        return mirrored, wall_x, wall_y, wall_z, inward_x, inward_y, inward_z

    @njit
    def mirror_planes(P, obstacle_box, x_built_x, x_built_y, x_built_z, xi_x, xi_y, xi_z):
        """(mirrored, wall, inward) of the planes i's images are mirrored across: the walls within h of xi (reused
        lists: within list_reach of x_built, where i was at the list's build), then the obstacles' faces where
        nearer (near_obstacles)."""
        if LIST_SKIN > 0:
            mirrored, wall_x, wall_y, wall_z = near_walls_within(P, x_built_x, x_built_y, x_built_z, list_reach(P))
        else:
            mirrored, wall_x, wall_y, wall_z = near_walls(P, xi_x, xi_y, xi_z)
        return near_obstacles(P, obstacle_box, xi_x, xi_y, xi_z, mirrored, wall_x, wall_y, wall_z)

    @njit
    def solid(P, obstacle_box, y_x, y_y, y_z):
        """Whether an image at y lies in the solid: on or beyond a wall, or in or on an obstacle."""
        if (y_x <= P.box_min[0] or y_x >= P.box_max[0] or y_y <= P.box_min[1] or y_y >= P.box_max[1]
                or (DIM == 3 and (y_z <= P.box_min[2] or y_z >= P.box_max[2]))):
            return True
        for o in range(OBSTACLES):
            lo_x, lo_y, lo_z = real(obstacle_box[2 * o, 0]), real(obstacle_box[2 * o, 1]), real(obstacle_box[2 * o, 2])
            hi_x = real(obstacle_box[2 * o + 1, 0])
            hi_y = real(obstacle_box[2 * o + 1, 1])
            hi_z = real(obstacle_box[2 * o + 1, 2])
            if (y_x >= lo_x and y_x <= hi_x and y_y >= lo_y and y_y <= hi_y
                    and (DIM == 2 or (y_z >= lo_z and y_z <= hi_z))):
                return True
        return False

    return named(near_obstacles, mirror_planes, solid)
