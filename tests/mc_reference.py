"""Float64 numpy marching cubes driven by the generated tables (sphcore/mc/tables.py).

For small grids (say up to 40^3): the oracle the shaders and their mirrors are checked against,
itself checked against scikit-image in tests/test_mc_tables.py.
"""
import numpy as np

from sphcore.mc.tables import CASE_EDGES, CASE_VERTICES, EDGE_AXIS, EDGE_CORNERS

CORNER_OFFSETS = np.array([[k & 1, (k >> 1) & 1, (k >> 2) & 1] for k in range(8)])


def reference_marching_cubes(volume, level, spacing=(1.0, 1.0, 1.0)):
    """Isosurface `level` of `volume` (3D, sample (x, y, z) = volume[x, y, z]) as (verts, faces).

    verts: (V, 3) float64, in scikit-image's convention: verts[:, a] is the position along numpy
    axis a in samples, times spacing[a]. faces: (F, 3) int64 indices into verts, wound as the
    tables (right-hand normals point into the inside, values > level, as scikit-image's default).

    Welded: one vertex per crossed grid edge, shared by every triangle that uses it, keyed
    4 * (flat index of the edge's lower sample) + axis and placed by linear interpolation along
    the edge. A crossed edge one of whose samples equals `level` exactly has its vertex at that
    sample, keyed 4 * (flat index of the sample) + 3, so all edges meeting there share it;
    triangles that thereby repeat a vertex are dropped. Otherwise no triangle is degenerate.
    """
    v = np.asarray(volume, dtype=np.float64)
    cubes = np.stack(np.meshgrid(*[np.arange(n - 1) for n in v.shape], indexing="ij"), -1).reshape(-1, 3)
    corner_inside = [v[tuple((cubes + o).T)] > level for o in CORNER_OFFSETS]
    case = sum(inside.astype(np.int64) << k for k, inside in enumerate(corner_inside))

    # every triangle vertex of every cube, in table order: its cube and edge
    slots = np.arange(CASE_EDGES.shape[1]) < CASE_VERTICES[case][:, None]
    cube = np.broadcast_to(cubes[:, None, :], slots.shape + (3,))[slots]
    edge = CASE_EDGES[case][slots].astype(np.int64)

    lower = cube + CORNER_OFFSETS[EDGE_CORNERS[edge, 0]]
    upper = cube + CORNER_OFFSETS[EDGE_CORNERS[edge, 1]]
    axis = EDGE_AXIS[edge].astype(np.int64)
    v_lower, v_upper = v[tuple(lower.T)], v[tuple(upper.T)]
    at_lower, at_upper = v_lower == level, v_upper == level
    t = np.where(at_lower, 0.0, np.where(at_upper, 1.0, (level - v_lower) / (v_upper - v_lower)))
    flat_lower = np.ravel_multi_index(tuple(lower.T), v.shape)
    flat_upper = np.ravel_multi_index(tuple(upper.T), v.shape)
    key = np.where(at_lower, 4 * flat_lower + 3,
                   np.where(at_upper, 4 * flat_upper + 3, 4 * flat_lower + axis))
    position = (lower + t[:, None] * np.eye(3)[axis]) * np.asarray(spacing, dtype=np.float64)

    _, first, vertex = np.unique(key, return_index=True, return_inverse=True)
    faces = vertex.reshape(-1, 3).astype(np.int64)
    distinct = (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])
    return position[first], faces[distinct]
