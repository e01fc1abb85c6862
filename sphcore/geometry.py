"""Bodies from meshes (3D) and polygons (2D): their signed distance, the wall particles sampled from it
and the clipping of the fluid lattice (issue 33).

A body is a closed surface: an obstacle in the flow (fluid = "outside": the solid is its inside) or a
container (fluid = "inside": the solid is its outside). The signed distance sd is positive on the FLUID
side. Fluid lattice points are kept only where sd >= dx / 2 to every body. Wall particles are Adami et
al. 2012's dummy particles: the points of the wall lattice domain.box_min + (i + 0.5) dx (inside the
box: points beyond the box's walls are dropped, the box's mirror walls are there) with -h <= sd < dx / 2
(h: the support radius): the solid side to depth h, and the points within dx / 2 on the fluid side that
the fluid's clipping leaves empty. Where the surface lies on the lattice's cell faces (a box aligned with
it) that is the solid side alone, 0 < depth <= h, and the surface lies midway between the last wall
layer and the first fluid layer; where it does not (a tank rotated by 30 degrees), a wall layer on the
solid side alone would leave a gap of up to dx / 2 between the layers, and the kernel sums of the fluid
particles within h of the wall short of a full lattice's: measured on a square container at spacing
0.02 m, h = 4 dx, Wendland C2: at 45 degrees as low as 0.72, 43 % of those particles below 0.95; with
the gap filled, 1.000 for every one (tests/test_geometry.py). The fluid block's lattice is the wall
lattice where its corner lies on domain.box_min + k dx.

3D distances are point-triangle distances (trimesh.triangles.closest_point; the sign from the pseudo-normal
at the closest point, _inside), measured only for the lattice points near the surface and against the
triangles near them; the points beyond are signed a connected region at a time (a region of the lattice
that does not meet the surface's neighbourhood lies wholly on one side, sign from a ray test). 2D distances are
shapely's. A body's wall particles and its clipping of a block are cached on disk
(sphcore.paths.cache_dir("geometry")), keyed by the mesh file's bytes, the transform and the lattice.
"""
import hashlib
import io
import json
import math
import os
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sphcore.errors import CacheWarning, SceneError
from sphcore.output import atomic_savez
from sphcore.paths import cache_dir

CACHE_VERSION = 2  # raise when what a cache entry holds or how it is computed changes
MESH_SUFFIXES = (".stl", ".obj", ".ply")
MAX_MESH_BYTES = 256 * 2**20
TOLERANCE = 1e-4  # of dx: a point this near a threshold (dx / 2, h) counts as on the fluid side of dx / 2, inside h


@dataclass(frozen=True)
class Body:
    """A loaded body: `shape` is a trimesh.Trimesh (3D) or a shapely Polygon (2D), scaled, rotated and
    translated; `digest` hashes its source (the mesh file's bytes or the vertices) and the transform."""
    name: str
    fluid: str  # "outside": an obstacle; "inside": a container
    shape: object
    digest: str

    @property
    def dim(self):
        return 2 if hasattr(self.shape, "exterior") else 3

    @property
    def centroid(self):
        """The centroid of the enclosed area or volume [m] (moments are taken about it)."""
        if self.dim == 2:
            return np.array(self.shape.centroid.coords[0])
        return np.array(self.shape.center_mass)

    @property
    def bounds(self):
        """(lower corner, upper corner) of its bounding box [m]."""
        b = np.asarray(self.shape.bounds, np.float64).reshape(-1)
        return b[:self.dim], b[self.dim:]


def where(i, entry):
    """`bodies[i] ("name")` for a message."""
    name = entry.get("name") if isinstance(entry, dict) else None
    return f'bodies[{i}] ("{name}")' if isinstance(name, str) else f"bodies[{i}]"


def rotation(angles):
    """The rotation matrix of `angles` in degrees: one angle (2D), or about x, then y, then z (3D)."""
    if np.ndim(angles) == 0:
        c, s = math.cos(math.radians(angles)), math.sin(math.radians(angles))
        return np.array([[c, -s], [s, c]])
    (cx, cy, cz), (sx, sy, sz) = (np.cos(np.radians(angles)), np.sin(np.radians(angles)))
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rz @ ry @ rx


def transform(vertices, entry):
    """Scale, then rotate, then translate the (n, dim) `vertices` by a body entry's keys."""
    v = np.asarray(vertices, np.float64) * entry["scale"]
    return v @ rotation(entry["rotate"]).T + np.asarray(entry["translate"], np.float64)


def load_body(i, entry):
    """The Body of scene entry `bodies[i]` (its keys checked and its mesh path absolute: sphcore.scene);
    SceneError, naming it, where the file cannot be read or the shape is not closed."""
    at = where(i, entry)
    recipe = {k: entry[k] for k in ("scale", "rotate", "translate", "fluid")}
    if "polygon" in entry:
        import shapely

        vertices = transform(entry["polygon"], entry)
        polygon = shapely.Polygon(vertices)
        if not polygon.is_valid:
            raise SceneError(f"{at}: the polygon is not a simple closed polygon ({shapely.is_valid_reason(polygon)}); "
                             "give its vertices in order around it, with no edge crossing another")
        if polygon.area <= 0:
            raise SceneError(f"{at}: the polygon encloses no area")
        shapely.prepare(polygon)
        digest = hashlib.sha256(json.dumps([entry["polygon"], recipe]).encode()).hexdigest()
        return Body(entry["name"], entry["fluid"], polygon, digest)
    path = Path(entry["mesh"])
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise SceneError(f"{at}: mesh {path}: not an STL, OBJ or PLY file (by its name)")
    try:
        with open(path, "rb") as f:
            data = f.read(MAX_MESH_BYTES + 1)  # (/dev/zero renamed .stl would read until memory runs out)
    except FileNotFoundError:
        raise SceneError(f"{at}: mesh {path}: no such file") from None
    except OSError as e:
        raise SceneError(f"{at}: mesh {path}: cannot read ({e.strerror})") from None
    if len(data) > MAX_MESH_BYTES:
        raise SceneError(f"{at}: mesh {path} is larger than {MAX_MESH_BYTES >> 20} MiB")
    import trimesh

    try:
        mesh = trimesh.load(io.BytesIO(data), file_type=path.suffix.lower()[1:], force="mesh", process=True)
    except Exception as e:  # trimesh's loaders raise many kinds
        raise SceneError(f"{at}: mesh {path}: unreadable ({type(e).__name__}: {e})") from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise SceneError(f"{at}: mesh {path}: no triangles read (not a mesh file, or an empty one)")
    shared = np.unique(mesh.edges_sorted, axis=0, return_counts=True)[1]
    if (shared != 2).any() or not mesh.is_watertight:
        raise SceneError(f"{at}: mesh {path} is not closed: {(shared == 1).sum()} open edges (on one triangle only) "
                         f"and {(shared > 2).sum()} edges on more than two; a body needs a watertight surface")
    if not mesh.is_winding_consistent:
        raise SceneError(f"{at}: mesh {path}: its triangles are not wound consistently (inside and outside "
                         "cannot be told apart)")
    mesh = trimesh.Trimesh(transform(mesh.vertices, entry), mesh.faces, process=False)
    if mesh.volume < 0:  # wound inside out: the normals point in
        mesh.invert()
    digest = hashlib.sha256(hashlib.sha256(data).digest() + json.dumps(recipe).encode()).hexdigest()
    return Body(entry["name"], entry["fluid"], mesh, digest)


def signed_distance(body, points):
    """Distance [m] of each of `points` (n, dim) to the body's surface, positive on the fluid side (n,),
    float64. Exact at every point (trimesh's closest point and ray tests in 3D): slow for many points."""
    points = np.asarray(points, np.float64).reshape(-1, body.dim)
    if len(points) == 0:
        return np.zeros(0)
    if body.dim == 2:
        import shapely

        d = shapely.distance(body.shape.exterior, shapely.points(points))
        inside = shapely.contains_xy(body.shape, points[:, 0], points[:, 1])
    else:
        import trimesh

        inward = trimesh.proximity.signed_distance(body.shape, points)  # (trimesh: positive inside)
        d, inside = np.abs(inward), inward > 0
    return np.where(inside == (body.fluid == "inside"), d, -d)


def _region_distance(body, points, shape, dx, band):
    """Signed distance at the lattice points `points` (n, dim) of a grid of `shape` (lattice order), exact
    where it is within `band` (at least dx) of the surface; elsewhere +-inf with the right sign. 3D: the
    lattice in cells of 4^3 points; a cell whose centre lies farther than band + its radius rho from the
    surface holds no point within band (the distance is 1-Lipschitz); in the others each point is measured
    against the triangles within d(centre) + 2 rho of the centre (its closest one is among them). The rest
    are signed by connected region of the lattice: two neighbouring lattice points on either side of the
    surface are both within dx of it, so a region that does not meet the cells measured lies on one side."""
    if body.dim == 2 or len(points) == 0:
        return signed_distance(body, points)
    import trimesh
    from scipy import ndimage

    band, mesh, k = max(band, dx), body.shape, 4
    index = np.indices(shape).reshape(len(shape), -1).T
    cells = np.ceil(np.asarray(shape) / k).astype(int)
    cell = np.ravel_multi_index((index // k).T, cells)
    corner = np.indices(cells).reshape(len(shape), -1).T * k
    extent = np.minimum(corner + k, shape) - 1 - corner  # index span of each cell's points
    centre = points[0] + dx * (corner + extent / 2)
    rho = dx * (k - 1) * math.sqrt(3) / 2
    _, d_centre, _ = trimesh.proximity.closest_point(mesh, centre)
    near_cell = d_centre - rho <= band
    near = near_cell[cell]
    d = np.full(len(points), np.inf)
    inside = np.zeros(len(points), bool)
    # [1] each near point against the triangles near its cell
    order = np.argsort(cell, kind="stable")
    starts = np.searchsorted(cell[order], np.arange(len(centre) + 1))
    tree = mesh.triangles_tree
    pair_point, pair_triangle = [], []
    for c in np.flatnonzero(near_cell):
        r = d_centre[c] + 2 * rho
        candidates = np.fromiter(tree.intersection(np.concatenate([centre[c] - r, centre[c] + r])), np.int64)
        members = order[starts[c]:starts[c + 1]]
        pair_point.append(np.repeat(members, len(candidates)))
        pair_triangle.append(np.tile(candidates, len(members)))
    if pair_point:
        pair_point, pair_triangle = np.concatenate(pair_point), np.concatenate(pair_triangle)
        closest = np.empty((len(pair_point), 3))
        for a in range(0, len(pair_point), 1 << 20):  # chunks of 1 M pairs
            part = slice(a, a + (1 << 20))
            closest[part] = trimesh.triangles.closest_point(mesh.triangles[pair_triangle[part]], points[pair_point[part]])
        dist = np.linalg.norm(points[pair_point] - closest, axis=1)
        best = np.lexsort((pair_triangle, dist, pair_point))  # per point the nearest, ties to the lower triangle
        best = best[np.unique(pair_point[best], return_index=True)[1]]
        measured = pair_point[best]
        d[measured] = dist[best]
        inside[measured] = _inside(mesh, points[measured], closest[best], pair_triangle[best])
    # [2] the rest by connected region
    labels, count = ndimage.label(~near.reshape(shape))
    if count:
        first = np.unique(labels.reshape(-1), return_index=True)[1][1:]  # one point of each region (label 0: near)
        far = ~near
        inside[far] = mesh.contains(points[first])[labels.reshape(-1)[far] - 1]
    return np.where(inside == (body.fluid == "inside"), d, -d)


def _inside(mesh, points, closest, triangle):
    """Whether each of `points` is inside the closed `mesh`, from its closest point on `triangle`: the sign of
    (point - closest) . n with n the angle-weighted pseudo-normal of the face, edge or vertex the closest point
    lies on (Baerentzen & Aanaes 2005, IEEE TVCG 11(3), exact for a closed, consistently wound mesh)."""
    from trimesh.triangles import points_to_barycentric

    faces, normals = mesh.faces, mesh.face_normals
    bary = points_to_barycentric(mesh.triangles[triangle], closest)
    small = bary < 1e-6
    n = normals[triangle].copy()
    edge = small.sum(1) == 1  # on the edge opposite the vertex of the small coordinate: k = (j + 1) % 3
    if edge.any():
        edge_id = np.unique(mesh.edges_sorted, axis=0, return_inverse=True)[1].reshape(-1)
        edge_normal = np.zeros((edge_id.max() + 1, 3))
        np.add.at(edge_normal, edge_id, np.repeat(normals, 3, axis=0))
        k = (np.argmax(small[edge], 1) + 1) % 3
        n[edge] = edge_normal[edge_id[3 * triangle[edge] + k]]
    corner = small.sum(1) == 2  # at the vertex of the large coordinate
    if corner.any():
        vertex_normal = np.zeros((len(mesh.vertices), 3))
        np.add.at(vertex_normal, faces.reshape(-1), (mesh.face_angles[:, :, None] * normals[:, None, :]).reshape(-1, 3))
        j = np.argmax(bary[corner], 1)
        n[corner] = vertex_normal[faces[triangle[corner], j]]
    return np.einsum("ij,ij->i", points - closest, n) < 0


def _lattice(origin, dx, counts, lo, hi):
    """The points origin + i dx (i in [lo, hi) per axis) in lattice order (the last axis fastest)."""
    axes = [origin[a] + dx * np.arange(lo[a], hi[a]) for a in range(len(counts))]
    return np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, len(counts))


def _region(body, origin, dx, counts, margin):
    """Index range [lo, hi) of the lattice points within `margin` of the body's bounding box."""
    b_lo, b_hi = body.bounds
    lo = np.clip(np.ceil((b_lo - margin - origin) / dx), 0, counts).astype(int)
    hi = np.clip(np.floor((b_hi + margin - origin) / dx) + 1, 0, counts).astype(int)
    return lo, np.maximum(hi, lo)


_RECENT = {}  # path -> (the file's (mtime, size), its arrays): the entries _cached read last in this process (a
#              sweep validates the same body thousands of times); a file changed since is read again


def _remember(path, arrays, stamp, keep=32):
    """`arrays`, kept in _RECENT as the file at `path` with `stamp` (the oldest of more than `keep` dropped), read-only."""
    for values in arrays.values():
        if isinstance(values, np.ndarray):
            values.flags.writeable = False
    _RECENT[path] = stamp, arrays
    while len(_RECENT) > keep:
        _RECENT.pop(next(iter(_RECENT)))
    return arrays


def _cached(kind, body, lattice, compute):
    """compute() -> dict of arrays, kept on disk under cache_dir("geometry") by a hash of `kind`, the
    body's digest and `lattice` (json-able); read back with np.load(allow_pickle=False)."""
    key = hashlib.sha256(json.dumps([CACHE_VERSION, kind, body.digest, lattice]).encode()).hexdigest()
    path = cache_dir("geometry") / f"{kind}-{key[:40]}.npz"
    try:
        stamp = os.stat(path)
        if _RECENT.get(path, (None,))[0] == (stamp.st_mtime_ns, stamp.st_size):
            return _RECENT[path][1]
        with np.load(path, allow_pickle=False) as f:
            return _remember(path, {name: f[name] for name in f.files}, (stamp.st_mtime_ns, stamp.st_size))
    except FileNotFoundError:
        pass
    except Exception as e:  # damaged: compute it again and replace it
        warnings.warn(f"geometry cache entry {path} unreadable ({type(e).__name__}); computed again", CacheWarning)
    arrays = compute()
    try:
        os.makedirs(path.parent, exist_ok=True)
        atomic_savez(path, **arrays)
    except OSError as e:
        warnings.warn(f"geometry cache {path.parent} not writable ({e.strerror}); not cached", CacheWarning)
    return arrays


def box_lattice(box_min, box_max, dx):
    """The wall lattice: origin box_min + dx / 2 and its point counts per axis inside the box."""
    lo, hi = np.asarray(box_min, np.float64), np.asarray(box_max, np.float64)
    return lo + 0.5 * dx, np.floor((hi - lo) / dx + 1e-6).astype(int)


def body_walls(body, box_min, box_max, dx, h):
    """The wall particles of one body: their lattice indices (nb, dim) int64 on the wall lattice (box_lattice)
    in lattice order (-h <= sd < dx / 2: the module's docstring), and the deepest depth [m] of the solid lattice points in its region (inf where some lie
    beyond the wall layer). Cached on disk."""
    origin, counts = box_lattice(box_min, box_max, dx)
    lo, hi = _region(body, origin, dx, counts, h + dx)
    lattice = [origin.tolist(), dx, counts.tolist(), lo.tolist(), hi.tolist(), h]

    def compute():
        points = _lattice(origin, dx, counts, lo, hi)
        sd = _region_distance(body, points, tuple(hi - lo), dx, h)
        depth = -sd
        wall = (sd < (0.5 - TOLERANCE) * dx) & (depth <= h + TOLERANCE * dx)  # (the fluid: sd >= (0.5 - TOLERANCE) dx)
        grid = np.stack(np.meshgrid(*[np.arange(a, b) for a, b in zip(lo, hi)], indexing="ij"), -1)
        deepest = depth[depth > 0].max() if (depth > 0).any() else 0.0
        return {"index": grid.reshape(-1, len(counts))[wall].astype(np.int64), "deepest": np.float64(deepest)}

    arrays = _cached("walls", body, lattice, compute)
    index = arrays["index"]
    if index.ndim != 2 or index.shape[1] != len(counts) or ((index < 0) | (index >= counts)).any():
        raise SceneError(f"geometry cache: a damaged entry for body {body.name!r}; delete {cache_dir('geometry')}")
    return index, float(arrays["deepest"])


def wall_particles(bodies, box_min, box_max, dx, h):
    """Wall particles of every body: positions (nw, dim) float64 on the wall lattice, body by body in
    lattice order, and each one's body index (nw,) int32. A lattice point that two bodies claim is the
    first one's."""
    origin, counts = box_lattice(box_min, box_max, dx)
    dim = len(counts)
    index = [body_walls(body, box_min, box_max, dx, h)[0] for body in bodies]
    if not index:
        return np.zeros((0, dim)), np.zeros(0, np.int32)
    owner = np.concatenate([np.full(len(i), k, np.int32) for k, i in enumerate(index)])
    index = np.concatenate(index).reshape(-1, dim)
    first = np.zeros(len(index), bool)
    first[np.unique(np.ravel_multi_index(index.T, counts), return_index=True)[1]] = True
    return origin + dx * index[first], owner[first]


def fluid_mask(bodies, block_min, counts, dx):
    """Which points of a fluid block's lattice (block_min + (i + 0.5) dx, `counts` per axis, lattice
    order) lie at least dx / 2 from every body on its fluid side: a bool (prod(counts),). Cached on disk."""
    origin = np.asarray(block_min, np.float64) + 0.5 * dx
    counts = np.asarray(counts, int)
    keep = np.ones(tuple(counts), bool)
    for body in bodies:
        lo, hi = _region(body, origin, dx, counts, 2 * dx)
        lattice = [origin.tolist(), dx, counts.tolist(), lo.tolist(), hi.tolist()]

        def compute():
            points = _lattice(origin, dx, counts, lo, hi)
            sd = _region_distance(body, points, tuple(hi - lo), dx, dx)
            return {"keep": np.packbits(sd >= (0.5 - TOLERANCE) * dx)}

        n = int(np.prod(hi - lo))
        inside = np.unpackbits(_cached("clip", body, lattice, compute)["keep"], count=n).astype(bool)
        if len(inside) != n:
            raise SceneError(f"geometry cache: a damaged entry for body {body.name!r}; delete {cache_dir('geometry')}")
        region = tuple(slice(a, b) for a, b in zip(lo, hi))
        if body.fluid == "inside":  # a container: beyond its region is solid
            mask = np.zeros_like(keep)
            mask[region] = inside.reshape(hi - lo)
            keep &= mask
        else:
            keep[region] &= inside.reshape(hi - lo)
    return keep.reshape(-1)


def buried_keys(walls, box_min, box_max, dx):
    """The wall lattice's points (as sorted flat indices) that wall particles surround: wall points whose 2 dim
    lattice neighbours are wall points too. A fluid particle nearest one of them may have got into a body (buried:
    the health check then measures how deep)."""
    origin, counts = box_lattice(box_min, box_max, dx)
    index = np.rint((np.asarray(walls, np.float64) - origin) / dx).astype(np.int64)
    keys = np.sort(np.ravel_multi_index(index.T, counts, mode="clip"))
    surrounded = np.ones(len(index), bool)
    for axis in range(len(counts)):
        for step in (-1, 1):
            near = index.copy()
            near[:, axis] += step
            inside = (near[:, axis] >= 0) & (near[:, axis] < counts[axis])
            found = np.zeros(len(index), bool)
            at = np.ravel_multi_index(near[inside].T, counts)
            found[inside] = keys[np.minimum(np.searchsorted(keys, at), len(keys) - 1)] == at
            surrounded &= found | ~inside  # (beyond the box: the box's mirror wall)
    return np.sort(np.ravel_multi_index(index[surrounded].T, counts))


def buried(keys, x, box_min, box_max, dx):
    """Which of the particles at x (n, dim) lie nearest a wall lattice point of `keys` (buried_keys): bool (n,)."""
    if len(keys) == 0:
        return np.zeros(len(x), bool)
    origin, counts = box_lattice(box_min, box_max, dx)
    index = np.clip(np.rint((np.asarray(x, np.float64) - origin) / dx), 0, counts - 1).astype(np.int64)
    at = np.ravel_multi_index(index.T, counts)
    return keys[np.minimum(np.searchsorted(keys, at), len(keys) - 1)] == at
