"""Seed 2's baseline, the geometry-shader method: one invocation per cube classifies it and
writes its own vertices at slots taken from an atomic counter (arguments[3], cleared by the
host). The output order depends on scheduling; the welded mesh does not.

Mirror of shaders/mc/emit_cubes.comp: same names, same statement order, same step labels.
The atomic becomes a plain update in a sequential launch (invocations in index order).
"""
from functools import lru_cache

from numba import njit

from sphcore.mc.cubes import classify, cube_origin, cubes
from sphcore.workgroups import launcher


@lru_cache(maxsize=None)
def emit_cubes(spec):
    _, emit_vertex = cubes(spec)

    @njit
    def emit_cubes_main(c, params, volume, arguments, vertex_position, vertex_normal, vertex_key, case_vertices,
                        case_edges):
        P = params[0]
        # [1] one invocation per cube
        if c >= P.cube_total:
            return
        # [2] case and vertex count
        s_x, s_y, s_z = cube_origin(P, c)
        code = classify(P, volume, s_x, s_y, s_z)
        count = case_vertices[code]
        if count == 0:
            return
        # [3] take `count` output slots; past the capacity they are counted but not written (the
        #     host sees the total in arguments[3], enlarges the output and runs again)
        first = arguments[3]
        arguments[3] += count
        if first + count > P.capacity:
            return
        # [4] write the vertices
        for k in range(count):
            emit_vertex(P, volume, case_edges, vertex_position, vertex_normal, vertex_key, c, code, k, first + k)

    return launcher(emit_cubes_main, parallel=False)
