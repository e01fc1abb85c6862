"""Density and pressure, one invocation per particle. Neighbours from the grid (GRID) or all
pairs; wall and obstacle-face images (WALLS, OBSTACLES); linear or Tait equation of state (TAIT).

Mirror of shaders/sph/compute_density.comp: same names, same statement order, same step
labels. A GLSL vec3 local `v` is `v_x, v_y, v_z` here.
"""
from functools import lru_cache

import numpy as np
from numba import njit

from sphcore.sph.cells import cells
from sphcore.sph.obstacles import obstacles
from sphcore.workgroups import launcher



@njit
def neighbour_hash(id, image):
    """Order-independent fingerprint of a neighbour (id, image): a 32-bit mix summed over the set."""
    h = ((id * 8 + image) * 0x9E3779B1) & 0xFFFFFFFF
    h ^= h >> 15
    h = (h * 0x85EBCA77) & 0xFFFFFFFF
    h ^= h >> 13
    return h


@lru_cache(maxsize=None)
def compute_density(spec, real=np.float32):
    DIM, GRID, WALLS, TAIT, NEIGHBOUR_STATS = spec.DIM, spec.GRID, spec.WALLS, spec.TAIT, spec.NEIGHBOUR_STATS
    cell_of, cell_index, near_walls, reflected, range_count, range_cells = cells(spec, real)
    near_obstacles, solid = obstacles(spec, real)
    OBSTACLES = spec.OBSTACLES

    @njit
    def compute_density_main(i, params, particle_x, particle_rho, particle_p, cell_pyramid, cell_start,
                             particle_id, particle_neighbours, obstacle_box):
        P = params[0]
        # [1] one invocation per particle; the grid is rounded up to whole work groups
        if i >= P.n:
            return
        # [2] own position
        xi_x = particle_x[i, 0]
        xi_y = particle_x[i, 1]
        xi_z = particle_x[i, 2]
        # [3] wall images: within h of a wall, particle i also sees every particle mirrored across
        #     it (ghost fluid: free-slip boundary of Takeda et al. 1994). Bit a of `mirrored` says
        #     that the wall nearer to xi on axis a is within h; an obstacle's face in front of xi
        #     takes the place of its axis's wall where nearer (obstacles.glsl)
        mirrored, wall_x, wall_y, wall_z = near_walls(P, xi_x, xi_y, xi_z)
        mirrored, wall_x, wall_y, wall_z, inward_x, inward_y, inward_z = near_obstacles(
            P, obstacle_box, xi_x, xi_y, xi_z, mirrored, wall_x, wall_y, wall_z)
        # [4] sum (h^2 - r^2)^3 over every particle and image within h, self included (with
        #     NEIGHBOUR_STATS, also count them and sum a hash of each (id, image): the set's fingerprint). Image
        #     `image` mirrors the axes of its bits; the image of j is within h of xi exactly when j
        #     is within h of xi's own image xm, so the cells searched are those around xm.
        sum_w = real(0.0)
        found = 0
        fingerprint = 0
        for image in range(8):
            if (image & ~mirrored) != 0:
                continue
            xm_x, xm_y, xm_z = reflected(xi_x, xi_y, xi_z, wall_x, wall_y, wall_z, image)
            base_x, base_y, base_z = cell_of(P, xm_x, xm_y, xm_z)
            # [5] the 3^dim cells around xm, as ranges of sorted particles (cells.glsl: range_cells)
            for k in range(range_count()):
                start = 0
                end = int(P.n)
                if GRID:
                    inside, first, last = range_cells(P, base_x, base_y, base_z, k)
                    if not inside:
                        continue
                    start = int(cell_start[first])
                    end = int(cell_start[last]) + int(cell_pyramid[last])
                for j in range(start, end):
                    xk, yk, zk = reflected(particle_x[j, 0], particle_x[j, 1], particle_x[j, 2],
                                           wall_x, wall_y, wall_z, image)
                    if OBSTACLES > 0 and image != 0 and not solid(P, obstacle_box, xk, yk, zk):
                        continue  # (obstacles.glsl)
                    r_x = xi_x - xk
                    r_y = xi_y - yk
                    r_z = xi_z - zk
                    r2 = r_x * r_x + r_y * r_y + r_z * r_z
                    if r2 < P.h2:
                        q = P.h2 - r2
                        sum_w += q * q * q
                        if NEIGHBOUR_STATS:
                            found += 1
                            fingerprint = (fingerprint + neighbour_hash(np.int64(particle_id[j]), image)) & 0xFFFFFFFF
        # [6] rho_i = m sum_j W_poly6(r_ij, h)
        rho = P.density_coef * sum_w
        # [7] equation of state, clamped at 0 so that the free surface does not pull (tensile
        #     instability); attraction, where a scene wants it, comes from the cohesion term.
        #     linear: p = k (rho - rho_0) (seed 1); Tait: p = B ((rho / rho_0)^7 - 1) (Becker &
        #     Teschner 2007, seed 2), the power by multiplications
        p = P.stiffness * (rho - P.rest_density)
        if TAIT:
            ratio = rho / P.rest_density
            ratio2 = ratio * ratio
            ratio4 = ratio2 * ratio2
            p = P.stiffness * (ratio4 * ratio2 * ratio - real(1.0))
        p = max(p, real(0.0))
        # [8] store
        particle_rho[i] = rho
        particle_p[i] = p
        if NEIGHBOUR_STATS:
            particle_neighbours[i, 0] = found
            particle_neighbours[i, 1] = fingerprint

    return launcher(compute_density_main)
