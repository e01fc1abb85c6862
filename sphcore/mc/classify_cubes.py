"""Classify each cube (case 0..255, kept for the traversal) and put its vertex count into the
base of the HistoPyramid (seed 2). One invocation per cube.

Mirror of shaders/mc/classify_cubes.comp: same names, same statement order, same step labels.
"""
from functools import lru_cache

from numba import njit

from sphcore.mc.cubes import classify, cube_origin
from sphcore.workgroups import launcher


@lru_cache(maxsize=None)
def classify_cubes(spec):
    @njit
    def classify_cubes_main(c, params, volume, cube_case, cube_pyramid, case_vertices):
        P = params[0]
        # [1] one invocation per cube
        if c >= P.cube_total:
            return
        # [2] case from the 8 corners, and its vertex count
        s_x, s_y, s_z = cube_origin(P, c)
        code = classify(P, volume, s_x, s_y, s_z)
        cube_case[c] = code
        cube_pyramid[c] = case_vertices[code]

    return launcher(classify_cubes_main)
