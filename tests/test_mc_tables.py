"""The marching-cubes case tables: the committed files are the generator's output; every case is
a consistent patch of surface; through tests/mc_reference.py they give closed meshes, wound as
scikit-image's (right-hand normals point into the inside), with scikit-image's area and volume."""
import numpy as np
import pytest
from mc_reference import reference_marching_cubes
from numba import njit

from sphcore.mc import generate_tables
from sphcore.mc.tables import CASE_EDGES, CASE_VERTICES, CASE_WIDTH, EDGE_AXIS, EDGE_CORNERS, NO_EDGE

CORNERS = [tuple(int(k) for k in corners) for corners in EDGE_CORNERS]
# the six cube faces as sets of edges: face (a, side) holds the corners with offset `side` along a
FACES = [{e for e in range(12) if all((k >> a) & 1 == side for k in CORNERS[e])}
         for a in range(3) for side in (0, 1)]


def triangles(case):
    return CASE_EDGES[case, :CASE_VERTICES[case]].reshape(-1, 3).tolist()


def is_inside(case, corner):
    return (case >> corner) & 1 == 1


def directed_sides(faces):
    """The triangles' sides as (from, to) pairs, in the triangles' winding."""
    faces = np.asarray(faces)
    return [tuple(s) for s in np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]).tolist()]


def test_generated_files_match_the_generator():
    for path, text in generate_tables.sources().items():
        assert path.read_text() == text, f"{path} is stale: run python -m sphcore.mc.generate_tables"


def test_tables_follow_the_corner_and_edge_conventions():
    for e in range(12):
        a, j = divmod(e, 4)
        b, c = [axis for axis in range(3) if axis != a]
        lower, upper = CORNERS[e]
        assert EDGE_AXIS[e] == a
        assert lower == ((j & 1) << b) | ((j >> 1) << c) and upper == lower | (1 << a)
    assert CASE_EDGES.shape == (256, CASE_WIDTH)
    assert CASE_EDGES.dtype == CASE_VERTICES.dtype == EDGE_CORNERS.dtype == EDGE_AXIS.dtype == np.uint32


def test_each_case_uses_exactly_its_crossed_edges():
    assert CASE_VERTICES[0] == CASE_VERTICES[255] == 0
    assert CASE_WIDTH == CASE_VERTICES.max() and CASE_WIDTH % 3 == 0
    for case in range(256):
        n = CASE_VERTICES[case]
        assert n % 3 == 0 and np.all(CASE_EDGES[case, n:] == NO_EDGE), case
        crossed = {e for e in range(12) if is_inside(case, CORNERS[e][0]) != is_inside(case, CORNERS[e][1])}
        assert {e for t in triangles(case) for e in t} == crossed, case
        assert all(len(set(t)) == 3 for t in triangles(case)), case


def test_each_case_is_a_surface_patch_bounded_by_face_segments():
    """A triangle side inside the cube is shared by two triangles, in opposite directions, and joins
    edges of no common face (else the neighbour across that face could draw it too); any other
    side (the patch's boundary) lies in a cube face. On an ambiguous face (two diagonal corners
    inside) each boundary segment cuts off an inside corner alone: the one its two edges share."""
    for case in range(1, 255):
        sides = directed_sides(triangles(case))
        assert len(set(sides)) == len(sides), case
        for p, q in sides:
            face = next((f for f in FACES if p in f and q in f), None)
            if (q, p) in sides:
                assert face is None, (case, p, q)
                continue
            assert face is not None, (case, p, q)
            inside = {k for e in face for k in CORNERS[e] if is_inside(case, k)}
            if len(inside) == 2 and bin(min(inside) ^ max(inside)).count("1") == 2:
                assert set(CORNERS[p]) & set(CORNERS[q]) & inside, (case, p, q)


def assert_closed(verts, faces, grid_max):
    """Every mesh edge not in an outer face of the grid (0 or grid_max along some axis) is used by
    exactly two triangles, traversing it in opposite directions."""
    sides = directed_sides(faces)
    assert len(set(sides)) == len(sides), "a side traversed twice in the same direction"
    used = set(sides)
    for p, q in sides:
        if (q, p) not in used:
            on_outer_face = (verts[p] == verts[q]) & ((verts[p] == 0) | (verts[p] == grid_max))
            assert on_outer_face.any(), f"crack at {verts[p]} - {verts[q]}"


@pytest.mark.parametrize("seed", range(6))
def test_random_fields_give_closed_meshes(seed):
    volume = np.random.default_rng(seed).standard_normal((7, 8, 9))
    verts, faces = reference_marching_cubes(volume, 0.0)
    assert len(faces) > 100
    assert_closed(verts, faces, np.array(volume.shape) - 1)


def test_samples_at_the_level_weld_to_the_sample():
    """The plane x + y = 3 through samples: vertices at those samples, collapsed triangles dropped,
    the rest closed and of the plane's area."""
    x, y, _ = np.indices((6, 7, 4))
    verts, faces = reference_marching_cubes((x + y - 3).astype(float), 0.0)
    assert np.all((faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2]))
    assert np.allclose(verts[:, 0] + verts[:, 1], 3.0) and np.all(verts == np.round(verts))
    assert_closed(verts, faces, np.array([5, 6, 3]))
    assert area(verts, faces) == pytest.approx(3 * np.sqrt(2) * 3)


def sphere(n=32, centre=(15.3, 14.7, 15.1), radius=10.2):
    """Field R - |x - c| on an n^3 grid (larger inside) and the centre c."""
    x = np.indices((n, n, n)).astype(float)
    return radius - np.sqrt(sum((x[a] - centre[a]) ** 2 for a in range(3))), np.array(centre)


def torus(shape=(34, 32, 30), centre=(16.6, 15.8, 14.4), major=9.3, minor=3.7):
    """Field r - (distance to the circle of radius R about axis 2 through c), larger inside."""
    x = np.indices(shape).astype(float)
    d = [x[a] - centre[a] for a in range(3)]
    return minor - np.sqrt((np.sqrt(d[0] ** 2 + d[1] ** 2) - major) ** 2 + d[2] ** 2)


def area(verts, faces):
    a, b, c = verts[faces[:, 0]], verts[faces[:, 1]], verts[faces[:, 2]]
    return 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1).sum()


def signed_volume(verts, faces):
    """Sum of the tetrahedra (origin, triangle): the enclosed volume, negative where the triangles'
    right-hand normals point inwards."""
    a, b, c = verts[faces[:, 0]], verts[faces[:, 1]], verts[faces[:, 2]]
    return np.einsum("ij,ij->", a, np.cross(b, c)) / 6.0


def test_sphere_triangles_face_inwards():
    volume, centre = sphere()
    verts, faces = reference_marching_cubes(volume, 0.0)
    a, b, c = verts[faces[:, 0]], verts[faces[:, 1]], verts[faces[:, 2]]
    outwards = np.einsum("ij,ij->i", np.cross(b - a, c - a), (a + b + c) / 3 - centre)
    assert np.all(outwards < 0)
    assert_closed(verts, faces, np.array(volume.shape) - 1)


@pytest.mark.parametrize("field, spacing", [(sphere()[0], (1.0, 1.0, 1.0)), (torus(), (0.9, 1.0, 1.2))],
                         ids=["sphere", "torus"])
def test_agrees_with_scikit_image(field, spacing):
    measure = pytest.importorskip("skimage.measure")
    theirs = measure.marching_cubes(field, 0.0, spacing=spacing, method="lorensen")
    their_verts, their_faces = theirs[0].astype(np.float64), theirs[1]
    verts, faces = reference_marching_cubes(field, 0.0, spacing)
    assert area(verts, faces) == pytest.approx(area(their_verts, their_faces), rel=0.005)
    ours, theirs = signed_volume(verts, faces), signed_volume(their_verts, their_faces)
    assert np.sign(ours) == np.sign(theirs) and ours == pytest.approx(theirs, rel=0.01)


def test_tables_usable_from_numba():
    @njit
    def corner_sum(case):
        total = CASE_WIDTH
        for k in range(CASE_VERTICES[case]):
            e = CASE_EDGES[case, k]
            total += EDGE_CORNERS[e, 0] + EDGE_CORNERS[e, 1] + EDGE_AXIS[e]
        return total

    for case in (1, 90, 165, 254):
        edges = CASE_EDGES[case, :CASE_VERTICES[case]]
        assert corner_sum(case) == CASE_WIDTH + EDGE_CORNERS[edges].sum() + EDGE_AXIS[edges].sum()
