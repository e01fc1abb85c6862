"""The fluid's colour field at every sample of the volume, through the particles' neighbour
grid: c(x) = sum_j m / rho_j W_poly6(x - x_j, h), about 1 inside the fluid and 0 outside;
its isosurface c = 1/2 is the fluid's surface. One invocation per sample. The particles
must be sorted by cell (shaders/sph: count_cells .. apply_order) and their densities known.

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
    cell_of, _, _, _, range_count, range_cells = cells(spec)

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
        # [3] sum (h^2 - r^2)^3 / rho_j over the particles within h, from the cells around x
        #     (cells.glsl: range_cells); no wall images, so the surface closes along the walls
        base_x, base_y, base_z = cell_of(P, x_x, x_y, x_z)
        sum_w = f32(0.0)
        for k in range(range_count()):
            ok, first, last = range_cells(P, base_x, base_y, base_z, k)
            if not ok:
                continue
            start = cell_start[first]
            end = cell_start[last] + cell_pyramid[last]
            for j in range(start, end):
                r_x = x_x - particle_x[j, 0]
                r_y = x_y - particle_x[j, 1]
                r_z = x_z - particle_x[j, 2]
                r2 = r_x * r_x + r_y * r_y + r_z * r_z
                if r2 < P.h2:
                    q = P.h2 - r2
                    sum_w += q * q * q / particle_rho[j]
        # [4] c = m W_poly6's coefficient times the sum
        volume[i] = P.density_coef * sum_w

    return launcher(sample_field_main)
