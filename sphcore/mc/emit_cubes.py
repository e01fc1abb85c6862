"""Seed 2's baseline, the geometry-shader method, as a GPU's subgroups run it: one invocation per run of
CUBE_RUN cubes along z; for each cube of the runs, the subgroup's cubes with vertices take their output
slots with one atomic on a counter (arguments[3], cleared by the host), then the subgroup writes each such
cube's vertices together, one lane per vertex. The output order depends on scheduling; the welded mesh
does not.

Mirror of shaders/mc/emit_cubes.comp: same names, same statement order, same step labels. The shader's
subgroup operations split it into phases, as barriers do (sphcore/workgroups.py): `launch` runs the work
groups in order (the atomic becomes a plain update), each group's subgroups of SUBGROUP_SIZE invocations
in order, and per subgroup one loop over its invocations per phase; an invocation's locals that outlive a
phase (inside, s, low, c, code, count, offset) are per-subgroup arrays indexed by the lane. A subgroup
operation is the loop that computes it: subgroupAdd a sum over the lanes, subgroupExclusiveAdd the sum of
the lanes before, subgroupElect and subgroupBroadcastFirst lane 0, subgroupBallot and FindLSB the lanes
with vertices in order, subgroupShuffle(x, lane) the lane's x. The subgroup size changes only the output
order (NVIDIA's is 32, lavapipe's 8).
"""
from functools import lru_cache

import numpy as np
from numba import njit

from sphcore.mc.cubes import cube_face, cube_index, cube_origin, cubes
from sphcore.numba_cache import cached

SUBGROUP_SIZE = 32


@lru_cache(maxsize=None)
def emit_cubes(spec):
    CUBE_RUN = spec.CUBE_RUN
    _, emit_vertex = cubes(spec)

    @njit
    def emit_cubes_run(r, lane, params, volume, inside, s, low):
        P = params[0]
        # [1] one invocation per run: its first cube's corner 0 and that cube's lowest face; an invocation
        #     past the last run has no cubes, and every invocation reaches the subgroup operations
        nz = int(P.dim[2]) - 1
        runs = (nz + CUBE_RUN - 1) // CUBE_RUN
        inside[lane] = r < (int(P.dim[0]) - 1) * (int(P.dim[1]) - 1) * runs
        s[lane, 0], s[lane, 1], s[lane, 2] = cube_origin(P, r // runs * nz)
        s[lane, 2] = r % runs * CUBE_RUN
        low[lane] = cube_face(P, volume, s[lane, 0], s[lane, 1], s[lane, 2]) if inside[lane] else 0

    @njit
    def emit_cubes_cube(lane, params, volume, case_vertices, inside, s, low, c, code, count):
        P = params[0]
        # [2] cube j of the run: its case from its two faces, its vertex count
        nz = int(P.dim[2]) - 1
        c[lane] = 0
        code[lane] = 0
        count[lane] = 0
        if inside[lane] and s[lane, 2] < nz:
            high = cube_face(P, volume, s[lane, 0], s[lane, 1], s[lane, 2] + 1)
            c[lane] = cube_index(P, s[lane, 0], s[lane, 1], s[lane, 2])
            code[lane] = low[lane] | (high << 4)
            count[lane] = case_vertices[code[lane]]
            low[lane] = high
        s[lane, 2] += 1

    @njit(error_model="numpy")
    def launch(n_groups, local_size, params, volume, arguments, vertex_position, vertex_normal, vertex_key,
               case_vertices, case_edges):
        P = params[0]
        size = min(SUBGROUP_SIZE, local_size)
        inside = np.zeros(size, np.bool_)  # the subgroup's invocations' locals that outlive a phase
        s = np.zeros((size, 3), np.int64)
        low = np.zeros(size, np.int64)
        c = np.zeros(size, np.int64)
        code = np.zeros(size, np.int64)
        count = np.zeros(size, np.int64)
        offset = np.zeros(size, np.int64)
        for group in range(n_groups):
            for subgroup in range(0, local_size, size):
                lanes = min(size, local_size - subgroup)
                for lane in range(lanes):
                    emit_cubes_run(group * local_size + subgroup + lane, lane, params, volume, inside, s, low)
                for j in range(CUBE_RUN):
                    for lane in range(lanes):
                        emit_cubes_cube(lane, params, volume, case_vertices, inside, s, low, c, code, count)
                    # [3] the subgroup's cubes with vertices take their output slots with one atomic (the
                    #     subgroup's first invocation's); past the capacity they are counted but not written
                    #     (the host sees the total in arguments[3], enlarges the output and runs again)
                    total = 0
                    for lane in range(lanes):
                        offset[lane] = total
                        total += count[lane]
                    if total == 0:
                        continue
                    first = int(arguments[3])
                    arguments[3] += total
                    # [4] each cube with vertices, in lane order: its vertices written by the subgroup, one lane each
                    for lane in range(lanes):
                        if count[lane] == 0:
                            continue
                        lane_first = first + offset[lane]
                        for v in range(count[lane]):
                            if lane_first + v < P.capacity:
                                emit_vertex(P, volume, case_edges, vertex_position, vertex_normal, vertex_key,
                                            c[lane], code[lane], v, lane_first + v)

    return cached(launch)
