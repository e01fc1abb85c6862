"""The fluid's colour field at every sample of the volume, through the particles' neighbour
grid: c(x) = sum_j m / rho_j W_poly6(x - x_j, h), about 1 inside the fluid and 0 outside;
its isosurface c = 1/2 is the fluid's surface. One invocation per sample. The particles
must be sorted by cell (shaders/sph: count_cells .. apply_order) and their densities known.
With walls (WALLS), the particles' mirror images across the walls count too, as in the density,
so the field stays about 1 up to a wall; and the field is 0 beyond the walls, so the surface
closes there (sphcore/surface.py: sample_grid puts each wall halfway between two samples).

Mirror of shaders/mc/sample_field.comp: same names, same statement order, same step labels.
`spec` is the scene's Spec (shaders/sph/constants.glsl), with GRID on.
"""
from functools import lru_cache

import numpy as np
from numba import njit

from sphcore.sph.cells import cells
from sphcore.workgroups import launcher

f32 = np.float32


@lru_cache(maxsize=None)
def sample_field(spec):
    WALLS = spec.WALLS
    cell_of = cells(spec).cell_of
    near_walls = cells(spec).near_walls
    reflected = cells(spec).reflected
    range_count = cells(spec).range_count
    range_cells = cells(spec).range_cells

    @njit
    def sample_field_main(i, params, volume, particle_x, particle_rho, cell_pyramid, cell_start):
        P = params[0]
        # [1] one invocation per sample
        if i >= int(P.dim[0]) * int(P.dim[1]) * int(P.dim[2]):
            return
        # [2] the sample's position
        s_x, s_y, s_z = i // (int(P.dim[1]) * int(P.dim[2])), i // int(P.dim[2]) % int(P.dim[1]), i % int(P.dim[2])
        x_x = P.origin[0] + f32(s_x) * P.spacing[0]
        x_y = P.origin[1] + f32(s_y) * P.spacing[1]
        x_z = P.origin[2] + f32(s_z) * P.spacing[2]
        # [3] beyond a wall: outside the fluid, so the surface closes at the wall
        if WALLS and (x_x < P.box_min[0] or x_y < P.box_min[1] or x_z < P.box_min[2] or x_x > P.box_max[0]
                      or x_y > P.box_max[1] or x_z > P.box_max[2]):
            volume[i] = f32(0.0)
            return
        # [4] wall images (cells.glsl: near_walls, reflected): within h of a wall, x also sees every
        #     particle mirrored across it; the image of j is within h of x exactly when j is within h of
        #     x's own image xm, so the cells searched are those around xm
        mirrored, wall_x, wall_y, wall_z = near_walls(P, x_x, x_y, x_z)
        # [5] sum (h^2 - r^2)^3 / rho_j over the particles and images within h, from the cells around
        #     each image xm of x (cells.glsl: range_cells)
        sum_w = f32(0.0)
        for image in range(8):
            if (image & ~mirrored) != 0:
                continue
            xm_x, xm_y, xm_z = reflected(x_x, x_y, x_z, wall_x, wall_y, wall_z, image)
            base_x, base_y, base_z = cell_of(P, xm_x, xm_y, xm_z)
            for k in range(range_count()):
                ok, first, last = range_cells(P, base_x, base_y, base_z, k)
                if not ok:
                    continue
                start = cell_start[first]
                end = cell_start[last] + cell_pyramid[last]
                for j in range(start, end):
                    r_x = xm_x - particle_x[j, 0]
                    r_y = xm_y - particle_x[j, 1]
                    r_z = xm_z - particle_x[j, 2]
                    r2 = r_x * r_x + r_y * r_y + r_z * r_z
                    if r2 < P.h2:
                        q = P.h2 - r2
                        sum_w += q * q * q / particle_rho[j]
        # [6] c = m W_poly6's coefficient times the sum
        volume[i] = P.density_coef * sum_w

    return launcher(sample_field_main)
