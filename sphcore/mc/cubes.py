"""Marching-cubes helpers shared by the classify, traverse and per-cube mirrors.

Mirror of shaders/mc/cubes.glsl: same names, same statements. GLSL reads the parameter block
as a global `P` and the buffers as globals; here they are arguments. A GLSL uvec3 is three ints.
The small helpers are inlined into their callers (inline="always"): the per-cube work is a few
nanoseconds, so a call and the re-reading of P's fields would otherwise cost as much again.
"""
from functools import lru_cache

import numpy as np
from numba import njit

from sphcore.mc.tables import CASE_WIDTH, EDGE_AXIS, EDGE_CORNERS

f32 = np.float32
u32 = np.uint32


@njit(inline="always")
def sample_index(P, s_x, s_y, s_z):
    """Index of sample s in the volume."""
    return (s_x * int(P.dim[1]) + s_y) * int(P.dim[2]) + s_z


@njit(inline="always")
def cube_origin(P, c):
    """Sample coordinates of cube c's corner 0 (by 32-bit unsigned division, as in GLSL)."""
    ny = P.dim[1] - u32(1)
    nz = P.dim[2] - u32(1)
    c = u32(c)
    return int(c // (ny * nz)), int(c // nz % ny), int(c % nz)


@njit(inline="always")
def cube_index(P, s_x, s_y, s_z):
    """Index of the cube with corner 0 at sample s (cube_origin's inverse)."""
    return (s_x * (int(P.dim[1]) - 1) + s_y) * (int(P.dim[2]) - 1) + s_z


@njit(inline="always")
def corner_offset(k):
    """Offset of corner k from corner 0 of its cube."""
    return k & 1, (k >> 1) & 1, (k >> 2) & 1


@njit(inline="always")
def classify(P, volume, s_x, s_y, s_z):
    """Case of the cube with corner 0 at sample s: bit k set where corner k is inside."""
    code = 0
    for k in range(8):
        o_x, o_y, o_z = corner_offset(k)
        if volume[sample_index(P, s_x + o_x, s_y + o_y, s_z + o_z)] > P.isolevel:
            code |= 1 << k
    return code


@njit(inline="always")
def cube_face(P, volume, s_x, s_y, s_z):
    """The bits of corners 0-3 (a cube's face at its lowest z) of the cube with corner 0 at sample s:
    classify(s) is cube_face(s) | cube_face(s + (0, 0, 1)) << 4."""
    i = sample_index(P, s_x, s_y, s_z)
    x = int(P.dim[1]) * int(P.dim[2])
    y = int(P.dim[2])
    face = 0
    if volume[i] > P.isolevel:
        face |= 1
    if volume[i + x] > P.isolevel:
        face |= 2
    if volume[i + y] > P.isolevel:
        face |= 4
    if volume[i + x + y] > P.isolevel:
        face |= 8
    return face


@lru_cache(maxsize=None)
def cubes(spec):
    """(gradient, emit_vertex) with the options of `spec` (MIDPOINT, FORWARD_NORMALS) compiled in."""
    MIDPOINT, FORWARD_NORMALS = spec.MIDPOINT, spec.FORWARD_NORMALS

    @njit(inline="always")
    def difference(P, volume, s, a):
        """Component a of the gradient at sample s (the body of gradient's loop over axes)."""
        lo_a = s[a]
        hi_a = s[a]
        if FORWARD_NORMALS:
            if s[a] + 1 < int(P.dim[a]):
                hi_a += 1
            else:
                lo_a -= 1
        else:
            if s[a] > 0:
                lo_a -= 1
            if s[a] + 1 < int(P.dim[a]):
                hi_a += 1
        lo = (lo_a if a == 0 else s[0], lo_a if a == 1 else s[1], lo_a if a == 2 else s[2])
        hi = (hi_a if a == 0 else s[0], hi_a if a == 1 else s[1], hi_a if a == 2 else s[2])
        return (volume[sample_index(P, hi[0], hi[1], hi[2])] - volume[sample_index(P, lo[0], lo[1], lo[2])]) / (
            f32(hi_a - lo_a) * P.spacing[a])

    @njit(inline="always")
    def gradient(P, volume, s_x, s_y, s_z):
        """Gradient of the volume at sample s: central differences, one-sided on the volume's faces
        (FORWARD_NORMALS: forward differences, backward on the last sample), per axis over the spacing."""
        s = (s_x, s_y, s_z)
        return difference(P, volume, s, 0), difference(P, volume, s, 1), difference(P, volume, s, 2)

    @njit
    def emit_vertex(P, volume, case_edges, vertex_position, vertex_normal, vertex_key, c, code, k, v):
        """Write vertex k of cube c (case `code`) to output slot v: its position on the edge by linear
        interpolation (MIDPOINT: the edge's midpoint), its unit normal against the gradient (towards
        lower values, outwards of a bright object, as scikit-image's), and a key naming its edge,
        4 (lower sample) + axis, or its sample, 4 sample + 3, where the value there equals the
        isolevel exactly: the host welds vertices with equal keys into one."""
        e = case_edges[code * CASE_WIDTH + k]
        axis = EDGE_AXIS[e]
        s_x, s_y, s_z = cube_origin(P, c)
        o_x, o_y, o_z = corner_offset(EDGE_CORNERS[e, 0])
        a_x, a_y, a_z = s_x + o_x, s_y + o_y, s_z + o_z
        o_x, o_y, o_z = corner_offset(EDGE_CORNERS[e, 1])
        b_x, b_y, b_z = s_x + o_x, s_y + o_y, s_z + o_z
        va = volume[sample_index(P, a_x, a_y, a_z)]
        vb = volume[sample_index(P, b_x, b_y, b_z)]
        t = f32(0.5) if MIDPOINT else (P.isolevel - va) / (vb - va)
        key = 4 * sample_index(P, a_x, a_y, a_z) + axis
        if not MIDPOINT and t == f32(0.0):
            key = 4 * sample_index(P, a_x, a_y, a_z) + 3
        if not MIDPOINT and t == f32(1.0):
            key = 4 * sample_index(P, b_x, b_y, b_z) + 3
        x_x, x_y, x_z = f32(a_x), f32(a_y), f32(a_z)
        if axis == 0:
            x_x += t
        elif axis == 1:
            x_y += t
        else:
            x_z += t
        ga_x, ga_y, ga_z = gradient(P, volume, a_x, a_y, a_z)
        gb_x, gb_y, gb_z = gradient(P, volume, b_x, b_y, b_z)
        g_x = ga_x * (f32(1.0) - t) + gb_x * t
        g_y = ga_y * (f32(1.0) - t) + gb_y * t
        g_z = ga_z * (f32(1.0) - t) + gb_z * t
        g_norm = np.sqrt(g_x * g_x + g_y * g_y + g_z * g_z)
        vertex_position[v, 0] = P.origin[0] + x_x * P.spacing[0]
        vertex_position[v, 1] = P.origin[1] + x_y * P.spacing[1]
        vertex_position[v, 2] = P.origin[2] + x_z * P.spacing[2]
        vertex_normal[v, 0] = -g_x / g_norm if g_norm > f32(0.0) else f32(0.0)
        vertex_normal[v, 1] = -g_y / g_norm if g_norm > f32(0.0) else f32(0.0)
        vertex_normal[v, 2] = -g_z / g_norm if g_norm > f32(0.0) else f32(0.0)
        vertex_key[v] = key

    return gradient, emit_vertex
