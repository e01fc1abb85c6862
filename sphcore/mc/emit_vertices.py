"""One invocation per output vertex (dispatched indirectly, write_arguments): walk the
HistoPyramid from its top down to the cube that holds vertex v, then place the vertex on
the cube's edge (seed 2). Vertices come out in cube order, 3 per triangle.

Mirror of shaders/mc/emit_vertices.comp: same names, same statement order, same step labels.
The launch takes its group count from arguments[0] and [1], as vkCmdDispatchIndirect does.
"""
from functools import lru_cache

from numba import njit

from sphcore.mc.cubes import cubes
from sphcore.pyramid import level_offset
from sphcore.workgroups import launcher


@lru_cache(maxsize=None)
def emit_vertices(spec):
    _, emit_vertex = cubes(spec)

    @njit
    def emit_vertices_main(v, params, volume, cube_case, cube_pyramid, arguments, vertex_position,
                           vertex_normal, vertex_key, case_edges):
        P = params[0]
        # [1] one invocation per output vertex (the dispatch may be two-dimensional)
        if v >= min(arguments[3], P.capacity):
            return
        # [2] from the top down: at each level step over the children whose vertices all come
        #     before v (start counts them), and descend into the child that holds v
        node = 0
        start = 0
        for l in range(int(P.levels) - 1, -1, -1):
            offset = level_offset(P.cube_total, l)
            child = 8 * node
            count = cube_pyramid[offset + child]
            k = 0
            while k < 7 and v >= start + count:
                start += count
                child += 1
                count = cube_pyramid[offset + child]
                k += 1
            node = child
        # [3] node is now the cube; v is its vertex v - start
        emit_vertex(P, volume, case_edges, vertex_position, vertex_normal, vertex_key, node, cube_case[node], v - start, v)

    return launcher(emit_vertices_main)
