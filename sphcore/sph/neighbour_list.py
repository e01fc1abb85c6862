"""The neighbour lists (dfsph.py: written by compute_density's scan), walked by compute_forces, and under
DFSPH by dfsph_factor, dfsph_residual and dfsph_velocity. GLSL reads particle_x and dfsph_neighbours as
buffers the including shader declares; here they are arguments, after the parameter block.

Mirror of shaders/sph/neighbour_list.glsl: same names, same statements. A GLSL vec3 `v` is
`v_x, v_y, v_z`; the out parameters j, image, r, r2 and rlen are returned before the direction.
"""
from functools import lru_cache

import numpy as np
from numba import njit

from sphcore.sph.cells import cells
from sphcore.sph.dfsph import IMAGE_SHIFT, NEIGHBOUR_MASK
from sphcore.sph.pairs import pairs


@lru_cache(maxsize=None)
def neighbour_list(spec, real=np.float32):
    reflected = cells(spec, real)[3]
    pair_direction = pairs(real)

    @njit
    def listed_pair(P, particle_x, dfsph_neighbours, i, slot, xi_x, xi_y, xi_z, wall_x, wall_y, wall_z,
                    inward_x, inward_y, inward_z):
        """Entry `slot` of particle i's list: (j, image, r_x, r_y, r_z, r2, rlen, r_hat_x, r_hat_y, r_hat_z)."""
        pair = int(dfsph_neighbours[slot * P.n + i])
        j = pair & NEIGHBOUR_MASK
        image = pair >> IMAGE_SHIFT
        xk, yk, zk = particle_x[j, 0], particle_x[j, 1], particle_x[j, 2]
        if image != 0:
            xk, yk, zk = reflected(xk, yk, zk, wall_x, wall_y, wall_z, image)  # (most entries are particles)
        r_x = xi_x - xk
        r_y = xi_y - yk
        r_z = xi_z - zk
        r2 = r_x * r_x + r_y * r_y + r_z * r_z
        rlen = np.sqrt(r2)
        r_hat_x, r_hat_y, r_hat_z = pair_direction(r_x, r_y, r_z, rlen, i, j, image, inward_x, inward_y, inward_z)
        return j, image, r_x, r_y, r_z, r2, rlen, r_hat_x, r_hat_y, r_hat_z

    return listed_pair
