"""The neighbour lists (dfsph.py: written by compute_density's scan), walked (walk.py) by compute_forces and
wall_pressure, by compute_density between builds of reused lists, and under DFSPH by dfsph_factor, dfsph_residual
and dfsph_velocity (with GRADIENTS the factor stores each entry's
gradient, which the sweeps read). GLSL reads particle_x, neighbours and neighbour_gradients as buffers the
including shader declares; here they are arguments, after the parameter block.

A walk goes through the slots from 0 in order, keeping the last chunk it loaded in `chunk`.

Mirror of shaders/sph/neighbour_list.glsl: same names, same statements. A GLSL vec3 `v` is
`v_x, v_y, v_z`, a uvec4 a 4-tuple; the inout parameter chunk and the out parameters j, image, r, r2 and rlen
are returned before the direction.
"""
from functools import lru_cache

import numpy as np
from numba import njit

from sphcore.sph import named
from sphcore.sph.cells import cells
from sphcore.sph.dfsph import IMAGE_SHIFT, NEIGHBOUR_MASK, lane_of, list_slots, load_chunk
from sphcore.sph.kernels import kernels
from sphcore.sph.pairs import pairs


@lru_cache(maxsize=None)
def neighbour_list(spec, real=np.float32):
    reflected = cells(spec, real).reflected
    pair_direction = pairs(real)
    pair_gradient = kernels(spec, real).pair_gradient
    GRADIENTS, LIST_BY_PARTICLE, LIST_CHUNKS = spec.GRADIENTS, spec.LIST_BY_PARTICLE, spec.LIST_CHUNKS
    list_slot = list_slots(spec)

    @njit
    def listed_word(P, neighbours, i, slot, chunk):
        """Entry `slot` of particle i's list as written (j | image << IMAGE_SHIFT), and the chunk: lists in chunks
        (LIST_CHUNKS) are read a chunk of 4 slots at a time, one 16-byte load at each fourth slot (dfsph.glsl)."""
        if LIST_BY_PARTICLE or not LIST_CHUNKS:
            return int(neighbours[list_slot(P, i, slot)]), chunk
        if (slot & 3) == 0:
            chunk = load_chunk(P, neighbours, i, slot)
        return lane_of(chunk, slot & 3), chunk

    @njit
    def listed_distance(P, particle_x, neighbours, i, slot, chunk, xi_x, xi_y, xi_z, wall_x, wall_y, wall_z):
        """Entry `slot` of particle i's list: (chunk, j, image, r_x, r_y, r_z, r2)."""
        pair, chunk = listed_word(P, neighbours, i, slot, chunk)
        j = pair & NEIGHBOUR_MASK
        image = pair >> IMAGE_SHIFT
        xk, yk, zk = particle_x[j, 0], particle_x[j, 1], particle_x[j, 2]
        if image != 0:
            xk, yk, zk = reflected(xk, yk, zk, wall_x, wall_y, wall_z, image)  # (most entries are particles)
        r_x = xi_x - xk
        r_y = xi_y - yk
        r_z = xi_z - zk
        return chunk, j, image, r_x, r_y, r_z, r_x * r_x + r_y * r_y + r_z * r_z

    @njit
    def listed_pair(P, particle_x, neighbours, i, slot, chunk, xi_x, xi_y, xi_z, wall_x, wall_y, wall_z,
                    inward_x, inward_y, inward_z):
        """The same, with (..., r2, rlen, r_hat_x, r_hat_y, r_hat_z): the direction from the entry to i."""
        chunk, j, image, r_x, r_y, r_z, r2 = listed_distance(P, particle_x, neighbours, i, slot, chunk, xi_x,
                                                             xi_y, xi_z, wall_x, wall_y, wall_z)
        rlen = np.sqrt(r2)
        r_hat_x, r_hat_y, r_hat_z = pair_direction(r_x, r_y, r_z, rlen, i, j, image, inward_x, inward_y, inward_z)
        return chunk, j, image, r_x, r_y, r_z, r2, rlen, r_hat_x, r_hat_y, r_hat_z

    @njit
    def listed_gradient(P, particle_x, neighbours, neighbour_gradients, i, slot, chunk, xi_x, xi_y, xi_z, wall_x,
                        wall_y, wall_z, inward_x, inward_y, inward_z):
        """Entry `slot` of particle i's list under DFSPH: (chunk, j, image, g_x, g_y, g_z), g = V grad_i W_ik.
        With GRADIENTS, as dfsph_factor stored it this step; else computed again as dfsph_factor computed it."""
        if GRADIENTS:
            pair, chunk = listed_word(P, neighbours, i, slot, chunk)
            j = pair & NEIGHBOUR_MASK
            image = pair >> IMAGE_SHIFT
            k = list_slot(P, i, slot)
            return chunk, j, image, neighbour_gradients[k, 0], neighbour_gradients[k, 1], neighbour_gradients[k, 2]
        chunk, j, image, r_x, r_y, r_z, r2, rlen, r_hat_x, r_hat_y, r_hat_z = listed_pair(
            P, particle_x, neighbours, i, slot, chunk, xi_x, xi_y, xi_z, wall_x, wall_y, wall_z, inward_x,
            inward_y, inward_z)
        g = real(P.pressure_coef) / real(P.rest_density) * pair_gradient(P, r2, rlen, image)
        return chunk, j, image, -(g * r_hat_x), -(g * r_hat_y), -(g * r_hat_z)

    return named(listed_pair, listed_gradient, listed_distance)
