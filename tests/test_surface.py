"""Marching cubes (shaders/mc) against scikit-image, analytic shapes and each other; the
fluid's colour field and surface."""
import math

import numpy as np
import pytest

import sphcore
from conftest import VALIDATION, vulkan_or_skip
from mc_reference import reference_marching_cubes
from sphcore.surface import Extractor, marching_cubes, particle_surface, weld

measure = pytest.importorskip("skimage.measure")

COMBINATIONS = [("numba", "histopyramid"), ("numba", "per_cube"), ("vulkan", "histopyramid"), ("vulkan", "per_cube")]


def extract(volume, level, spacing=(1.0, 1.0, 1.0), backend="numba", method="histopyramid", **options):
    """marching_cubes through an Extractor, with the validation layers on for Vulkan (none may report)."""
    if backend == "vulkan":
        vulkan_or_skip()
        options["validation"] = VALIDATION
    with Extractor(volume.shape, spacing, backend=backend, method=method, **options) as extractor:
        mesh = weld(*extractor.extract(volume, level))
        if backend == "vulkan":
            assert extractor.device.ctx.validation_messages == []
    return mesh


def grid(shape, spacing=(1.0, 1.0, 1.0)):
    return np.stack(np.meshgrid(*[np.arange(k) * s for k, s in zip(shape, spacing)], indexing="ij"), -1)


def sphere(shape=(24, 26, 28), centre=(11.3, 12.6, 13.1), radius=8.3, spacing=(1.0, 1.0, 1.0)):
    """R - |x - c|: positive inside, level 0 (a distance field, so vertices sit on the sphere)."""
    return (radius - np.linalg.norm(grid(shape, spacing) - np.array(centre), axis=-1)).astype(np.float32)


def torus(shape=(30, 28, 20), major=8.0, minor=3.2):
    x = grid(shape) - (np.array(shape) - 1) / 2
    ring = np.hypot(x[..., 0], x[..., 1]) - major
    return (minor - np.hypot(ring, x[..., 2])).astype(np.float32)


def metaballs(shape=(32, 32, 32), seed=3):
    """Five metaballs: sum of r_k^2 / |x - c_k|^2, level 1."""
    rng = np.random.default_rng(seed)
    x = grid(shape)
    field = np.zeros(shape)
    for centre, radius in zip(rng.uniform(8, np.array(shape) - 8, (5, 3)), rng.uniform(3, 5, 5)):
        field += radius**2 / (((x - centre) ** 2).sum(-1) + 1e-3)
    return field.astype(np.float32)


def plane_through_samples(shape=(12, 13, 14)):
    """x - 5: zero exactly on the samples of the plane x = 5."""
    return (grid(shape)[..., 0] - 5.0).astype(np.float32)


def cut_sphere(shape=(20, 20, 20)):
    """A sphere cut by three faces of the grid: the surface reaches the boundary, open there."""
    return sphere(shape, centre=(2.5, 3.0, 17.2), radius=9.0)


FIELDS = {"sphere": (sphere, 0.0), "torus": (torus, 0.0), "metaballs": (metaballs, 1.0),
          "plane": (plane_through_samples, 0.0), "boundary": (cut_sphere, 0.0)}


def area(verts, faces):
    a, b, c = (verts[faces[:, k]].astype(np.float64) for k in range(3))
    return 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)


def signed_volume(verts, faces):
    """Enclosed volume by the divergence theorem; negative for scikit-image's winding (right-hand
    normals point into the bright inside)."""
    a, b, c = (verts[faces[:, k]].astype(np.float64) for k in range(3))
    return np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0


def assert_valid(verts, faces, normals):
    assert verts.dtype == np.float32 and normals.dtype == np.float32 and faces.dtype == np.int32
    assert verts.shape == normals.shape and verts.shape[1:] == (3,) and faces.shape[1:] == (3,)
    assert np.isfinite(verts).all() and np.isfinite(normals).all()
    assert faces.min(initial=0) >= 0 and faces.max(initial=-1) < len(verts)
    assert (faces[:, 0] != faces[:, 1]).all() and (faces[:, 1] != faces[:, 2]).all() and (faces[:, 0] != faces[:, 2]).all()
    assert (area(verts, faces) > 0).all(), "degenerate (zero-area) triangles"
    assert len(np.unique(faces)) == len(verts), "unused vertices"
    assert np.allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-5)


@pytest.mark.parametrize("name", FIELDS)
def test_agrees_with_scikit_image(name):
    """Same vertices and triangle count as scikit-image's Lorensen method, area within 0.1 % and
    volume within 0.5 % (the polygons of a cube are split into triangles along other diagonals);
    area within 0.5 % of its default (Lewiner) method, which resolves ambiguous faces differently."""
    make, level = FIELDS[name]
    volume = make()
    spacing = (0.5, 0.7, 1.1)
    verts, faces, normals = sphcore.marching_cubes(volume, level, spacing)  # the package-level entry point
    assert_valid(verts, faces, normals)
    sk_verts, sk_faces, sk_normals, _ = measure.marching_cubes(volume, level, spacing=spacing, method="lorensen")
    assert len(faces) == len(sk_faces) and len(verts) == len(sk_verts)
    order, sk_order = np.lexsort(verts.T), np.lexsort(sk_verts.T)
    assert np.abs(verts[order] - sk_verts[sk_order]).max() < 1e-4
    assert area(verts, faces).sum() == pytest.approx(area(sk_verts, sk_faces).sum(), rel=1e-3)
    assert signed_volume(verts, faces) == pytest.approx(signed_volume(sk_verts, sk_faces), rel=5e-3, abs=1e-6)
    # vertex normals: both from the gradient, towards lower values; they differ where the two
    # gradient estimates do (scikit-image's np.gradient at the samples, interpolated the same way)
    assert np.einsum("ij,ij->i", normals[order], sk_normals[sk_order]).min() > 0.8
    lewiner = measure.marching_cubes(volume, level, spacing=spacing)
    assert area(verts, faces).sum() == pytest.approx(area(lewiner[0], lewiner[1]).sum(), rel=5e-3)


def test_sphere_area_within_one_percent_from_below():
    """At 64^3 the area of a sphere is within 1 % of 4 pi r^2, and below it: with the distance
    field R - |x - c| (concave), linear interpolation puts every vertex on or inside the sphere."""
    radius, centre = 27.3, (31.7, 32.2, 31.4)
    verts, faces, normals = marching_cubes(sphere((64, 64, 64), centre, radius), 0.0)
    exact = 4 * math.pi * radius**2
    total = area(verts, faces).sum()
    assert 0.99 * exact < total < exact, f"area {total:.1f} against 4 pi r^2 = {exact:.1f}"
    assert (np.linalg.norm(verts - np.array(centre), axis=1) <= radius + 1e-4).all()
    assert -signed_volume(verts, faces) == pytest.approx(4 / 3 * math.pi * radius**3, rel=1e-2)
    outward = (verts - np.array(centre)) / np.linalg.norm(verts - np.array(centre), axis=1)[:, None]
    assert np.einsum("ij,ij->i", normals, outward).min() > math.cos(math.radians(3.0))


def test_empty_full_and_constant_fields_give_empty_meshes():
    """scikit-image raises where the level is outside the data's range; we return an empty mesh."""
    volume = sphere()
    for level in (float(volume.max()) + 1, float(volume.min()) - 1):
        verts, faces, normals = marching_cubes(volume, level)
        assert verts.shape == (0, 3) and faces.shape == (0, 3) and normals.shape == (0, 3)
    with pytest.raises(ValueError):
        measure.marching_cubes(volume, float(volume.max()) + 1)


def test_plane_through_samples_has_exact_area():
    """The plane x = 5 through a row of samples: every vertex on a sample, area exactly (ny-1)(nz-1)."""
    verts, faces, _ = marching_cubes(plane_through_samples(), 0.0)
    assert np.all(verts[:, 0] == 5.0)
    assert area(verts, faces).sum() == pytest.approx(12 * 13)


def test_reference_implementation_agrees():
    """The shaders' mesh equals the plain-numpy reference's, vertex for vertex and triangle for triangle."""
    volume = metaballs((20, 18, 22))
    verts, faces, _ = marching_cubes(volume, 1.0)
    ref_verts, ref_faces = reference_marching_cubes(volume, 1.0)
    assert np.abs(verts - ref_verts).max() < 1e-4
    assert np.array_equal(faces, ref_faces)


def canonical(faces):
    """Triangles as a sorted array, each rotated to start at its smallest index (orientation kept)."""
    shift = np.argmin(faces, axis=1)
    rotated = np.stack([faces[np.arange(len(faces)), (shift + k) % 3] for k in range(3)], axis=1)
    return rotated[np.lexsort(rotated.T[::-1])]


@pytest.mark.parametrize("backend,method", COMBINATIONS)
@pytest.mark.parametrize("name", ["metaballs", "boundary", "plane"])
def test_backends_and_methods_give_the_same_mesh(name, backend, method):
    """Every backend and method gives the same triangles (in any order) and the same vertices
    within 1e-5 (GPU compilers may fuse multiply-adds) as numba's HistoPyramid."""
    make, level = FIELDS[name]
    volume = make()
    expected = extract(volume, level)
    verts, faces, normals = extract(volume, level, backend=backend, method=method)
    assert_valid(verts, faces, normals)
    assert np.array_equal(canonical(faces), canonical(expected[1]))
    assert np.abs(verts - expected[0]).max() < 1e-5
    assert np.abs(normals - expected[2]).max() < 1e-5


@pytest.mark.parametrize("backend", ["numba", "vulkan"])
def test_midpoint_and_forward_difference_options(backend):
    volume = sphere()
    verts, faces, normals = extract(volume, 0.0, backend=backend, midpoint=True)
    assert np.all(np.sort(np.modf(verts)[0], axis=1)[:, :2] == 0.0), "two coordinates on the grid"
    assert np.all(np.sort(np.modf(verts)[0], axis=1)[:, 2] == 0.5), "the third at an edge's midpoint"
    central = extract(volume, 0.0, backend=backend)
    forward = extract(volume, 0.0, backend=backend, forward_normals=True)
    assert np.array_equal(forward[1], central[1]) and np.array_equal(forward[0], central[0])
    assert_valid(*forward)
    dots = np.einsum("ij,ij->i", forward[2], central[2])
    assert dots.min() > 0.9 and dots.mean() < 0.9999, "forward differences are another estimate, close to central"


@pytest.mark.parametrize("backend,method", COMBINATIONS)
def test_output_too_small_is_enlarged_not_truncated(backend, method):
    volume = metaballs((20, 20, 20))
    expected = extract(volume, 1.0)
    if backend == "vulkan":
        vulkan_or_skip()
    with Extractor(volume.shape, backend=backend, method=method) as extractor:
        extractor.resize(7)  # room for 8 vertices
        position, normal, key = extractor.extract(volume, 1.0)
        assert extractor.sizes["capacity"] >= len(key) == 3 * len(expected[1])
    verts, faces, _ = weld(position, normal, key)
    assert np.array_equal(canonical(faces), canonical(expected[1]))


@pytest.mark.parametrize("backend", ["numba", "vulkan"])
@pytest.mark.parametrize("cube_run", [1, 3, 4, 40])
def test_per_cube_runs_give_the_same_mesh(backend, cube_run):
    """emit_cubes with runs of 1, 3, 4 and 40 cubes along z (31 cubes per row: runs cut short at the row's
    end, and one run longer than the row) gives numba's HistoPyramid triangles, also with room for only
    8 vertices at first (enlarged, not cut); on Vulkan, with the subgroup operations of the GPU's
    subgroup size, on numba with the mirror's 32."""
    volume = metaballs((20, 25, 32))
    expected = extract(volume, 1.0)
    verts, faces, normals = extract(volume, 1.0, backend=backend, method="per_cube", cube_run=cube_run)
    assert np.array_equal(canonical(faces), canonical(expected[1]))
    assert np.abs(verts - expected[0]).max() < 1e-5 and np.abs(normals - expected[2]).max() < 1e-5
    with Extractor(volume.shape, backend=backend, method="per_cube", cube_run=cube_run) as extractor:
        assert extractor.sizes["runs"] == 19 * 24 * -(-31 // cube_run)
        extractor.resize(7)
        again = weld(*extractor.extract(volume, 1.0))
    assert np.array_equal(canonical(again[1]), canonical(expected[1]))


def test_per_cube_run_length_is_checked_and_chosen_by_size():
    from sphcore.surface import RUN_FROM, default_cube_run
    for bad in (0, -2, 2.5, "4"):
        with pytest.raises(ValueError, match="cube_run"):
            Extractor((8, 8, 8), method="per_cube", cube_run=bad)
    assert default_cube_run((8, 8, 8)) == 1 and default_cube_run((129, 129, 129)) == 4
    assert default_cube_run((2, 2, RUN_FROM)) == 1 and default_cube_run((2, 2, RUN_FROM + 1)) == 4


def test_per_cube_on_a_device_without_subgroup_operations_says_so(monkeypatch):
    vulkan_or_skip()
    from sphcore.vk_runner import Context, VulkanError
    monkeypatch.setattr(Context, "_supports_subgroup_operations", lambda self: False)
    with pytest.raises(VulkanError, match="subgroup operations.*histopyramid"):
        Extractor((8, 8, 8), backend="vulkan", method="per_cube")
    with Extractor((8, 8, 8), backend="vulkan", method="histopyramid") as extractor:  # the other method needs none
        assert len(extractor.extract(sphere((8, 8, 8), (3.5, 3.5, 3.5), 2.5), 0.0)[2]) > 0


def test_bad_input_is_rejected_with_what_and_where():
    volume = sphere()
    with pytest.raises(ValueError, match="3D volume"):
        marching_cubes(volume[0], 0.0)
    with pytest.raises(ValueError, match="at least 2 samples"):
        marching_cubes(volume[:1], 0.0)
    broken = volume.copy()
    broken[3, 4, 5] = np.nan
    with pytest.raises(ValueError, match=r"non-finite.*\(3, 4, 5\)"):
        marching_cubes(broken, 0.0)
    with pytest.raises(ValueError, match="spacing"):
        marching_cubes(volume, 0.0, spacing=(1.0, 0.0, 1.0))
    with pytest.raises(ValueError, match="method"):
        marching_cubes(volume, 0.0, method="dual")
    with pytest.raises(ValueError, match="backend"):
        marching_cubes(volume, 0.0, backend="cuda")


@pytest.mark.parametrize("backend", ["numba", "vulkan"])
def test_particle_surface_wraps_the_fluid(backend):
    """A cube of particles at rest: the colour field is ~1 inside and 0 far outside, and its
    isosurface 1/2 encloses the particles' volume N dx^3 within 10 %, on both backends alike."""
    from sphcore.scene import Scene
    if backend == "vulkan":
        vulkan_or_skip()
    scene = Scene.from_dict({"name": "cube", "physics": {"model": "graphics", "dimension": 3, "gravity": False},
                             "domain": {"boundary": "open", "box_min": [0.0, 0.0, 0.0], "box_max": [0.3, 0.3, 0.3]},
                             "fluid": {"spacing": 0.01, "blocks": [{"min": [0.1, 0.1, 0.1], "max": [0.2, 0.2, 0.2]}]}})
    x = scene.initial_positions()
    verts, faces, normals, (volume, origin, spacing) = particle_surface(scene, x, backend=backend, with_field=True)
    assert_valid(verts, faces, normals)
    assert spacing == (scene.h / 2,) * 3
    inside = np.all(np.abs(grid(volume.shape, spacing) + origin - 0.15) < 0.03, axis=-1)
    assert np.abs(volume[inside] - 1.0).max() < 0.05
    assert volume[0, 0, 0] == 0.0
    assert -signed_volume(verts, faces) == pytest.approx(len(x) * 0.01**3, rel=0.10)
    assert (verts.min(0) > 0.1 - scene.h).all() and (verts.max(0) < 0.2 + scene.h).all()
    if backend == "vulkan":
        reference = particle_surface(scene, x, backend="numba", with_field=True)
        assert np.abs(reference[3][0] - volume).max() < 1e-5
        assert np.array_equal(canonical(faces), canonical(reference[1]))


def boundary_edges(faces):
    """Edges used by one face only (a closed, watertight mesh has none: each edge bounds two faces)."""
    edges = np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    unique, count = np.unique(edges, axis=0, return_counts=True)
    assert count.max(initial=2) <= 2, "an edge of more than two faces"
    return unique[count == 1]


@pytest.mark.parametrize("backend", ["numba", "vulkan"])
def test_particle_surface_closes_at_the_walls(backend):
    """A block of fluid in the corner of a box, touching the walls x = 0, y = 0, z = 0 and z = max: the
    field counts the wall images (about 1 on the samples next to a wall, as in the bulk) and is 0
    beyond the walls, so the surface is closed there, each wall halfway between two samples. The
    mesh is watertight, its volume is the particles' N dx^3 within 3 %, and it agrees between the
    backends. The same field without the samples beyond the walls leaves the mesh open (the holes
    this closes)."""
    from sphcore.scene import Scene
    if backend == "vulkan":
        vulkan_or_skip()
    box_max = np.array([0.1, 0.08, 0.09])
    scene = Scene.from_dict({"name": "corner", "physics": {"model": "graphics", "dimension": 3, "gravity": False},
                             "domain": {"box_min": [0.0, 0.0, 0.0], "box_max": box_max.tolist()},
                             "fluid": {"spacing": 0.01,
                                       "blocks": [{"min": [0.0, 0.0, 0.0], "max": [0.05, 0.04, 0.09]}]}})
    x = scene.initial_positions()
    verts, faces, normals, (volume, origin, spacing) = particle_surface(scene, x, backend=backend, with_field=True)
    assert_valid(verts, faces, normals)
    assert len(boundary_edges(faces)) == 0
    assert -signed_volume(verts, faces) == pytest.approx(len(x) * 0.01**3, rel=0.03)
    # the walls halfway between samples: the first sample half a spacing beyond x = y = z = 0 and the
    # last half a spacing beyond z = 0.09; every vertex within half a spacing of the box
    assert np.allclose(origin, -np.array(spacing) / 2) and max(spacing) <= scene.h / 2
    assert origin[2] + (volume.shape[2] - 1) * spacing[2] == pytest.approx(box_max[2] + spacing[2] / 2)
    assert (verts.min(0) >= -np.array(spacing) / 2).all() and verts[:, 2].max() <= box_max[2] + spacing[2] / 2
    assert (volume[0] == 0).all() and (volume[:, 0] == 0).all() and (volume[:, :, 0] == 0).all()
    assert (volume[:, :, -1] == 0).all()
    # with the images the samples next to a wall, inside the block, see a full neighbourhood: about 1
    assert np.abs(volume[1, 1:4, 1:-1] - 1.0).max() < 0.05
    open_faces = marching_cubes(volume[1:, 1:, 1:-1], 0.5)[1]
    assert len(boundary_edges(open_faces)) > 0
    if backend == "vulkan":
        reference = particle_surface(scene, x, backend="numba", with_field=True)
        assert np.abs(reference[3][0] - volume).max() < 1e-5
        assert np.array_equal(canonical(faces), canonical(reference[1]))
