"""Wall models, chosen by the closure constant NO_SLIP (scene key domain.wall_model): the velocity
of a particle's mirror image across walls and obstacle faces.

Mirror of shaders/sph/walls.glsl: same names, same statements (the models and their papers are
there). free_slip (Libersky et al. 1993): the image's normal velocity reversed; no_slip (Takeda et
al. 1994): its whole velocity reversed. A GLSL vec3 `v` is `v_x, v_y, v_z`.
"""
from functools import lru_cache

import numpy as np
from numba import njit
from sphcore.sph import named

WALL_MODELS = ("free_slip", "no_slip")  # scene key domain.wall_model -> NO_SLIP (index)


@lru_cache(maxsize=None)
def walls(spec, real=np.float32):
    NO_SLIP = spec.NO_SLIP

    @njit
    def free_slip(v_x, v_y, v_z, image):
        """Free slip: the components of the mirrored axes reversed."""
        return (-v_x if (image & 1) != 0 else v_x, -v_y if (image & 2) != 0 else v_y,
                -v_z if (image & 4) != 0 else v_z)

    @njit
    def no_slip(v_x, v_y, v_z):
        """No slip: the whole velocity reversed."""
        return -v_x, -v_y, -v_z

    @njit
    def image_velocity(v_x, v_y, v_z, image):
        """Velocity of the image `image` of a particle moving at v (image 0: the particle itself)."""
        if image == 0:
            return v_x, v_y, v_z
        if NO_SLIP:
            return no_slip(v_x, v_y, v_z)
        return free_slip(v_x, v_y, v_z, image)

    return named(free_slip, no_slip, image_velocity)
