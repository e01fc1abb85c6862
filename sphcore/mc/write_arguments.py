"""Read the vertex total from the top of the HistoPyramid and write the indirect dispatch
arguments of emit_vertices, so that no count travels to the host (seed 2). One invocation.

Mirror of shaders/mc/write_arguments.comp: same names, same statement order, same step labels.
The work-group size, gl_WorkGroupSize.x in GLSL, is the launch's local size, passed in.
"""
from functools import lru_cache

from numba import njit

from sphcore.pyramid import level_offset
from sphcore.workgroups import launcher

MAX_GROUPS_X = 65535  # the least maxComputeWorkGroupCount[0] Vulkan allows


@lru_cache(maxsize=None)
def write_arguments(spec):
    @njit
    def write_arguments_main(gid, params, local_size, cube_pyramid, arguments):
        P = params[0]
        # [1] one invocation
        if gid != 0:
            return
        # [2] vertices to emit: all of them, or as many as the output holds (the host sees the
        #     total in arguments[3], enlarges the output and runs again: nothing is cut silently)
        total = cube_pyramid[level_offset(P.cube_total, P.levels)]
        groups = (min(total, P.capacity) + local_size - 1) // local_size
        # [3] (x, y, z) work groups, x at most MAX_GROUPS_X; then the total
        arguments[0] = min(groups, MAX_GROUPS_X)
        arguments[1] = (groups + MAX_GROUPS_X - 1) // MAX_GROUPS_X
        arguments[2] = 1
        arguments[3] = total

    return launcher(write_arguments_main, parallel=False)
