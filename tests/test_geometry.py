"""Bodies from meshes and polygons, host side (issue 33; sphcore/geometry.py): signed distances, wall particles,
the fluid's clipping, the geometry cache, the shipped meshes and the scene's refusals. No simulation runs.

The oracles are computed here another way: a square's and a box's distance in closed form, trimesh's exact
signed distance at every lattice point (the module measures only near the surface), a kernel sum over a full
lattice."""
import json
import math
import time
import tomllib
import warnings

import numpy as np
import pytest

trimesh = pytest.importorskip("trimesh")
pytest.importorskip("shapely")

from sphcore import geometry  # noqa: E402
from sphcore.errors import CacheWarning  # noqa: E402
from sphcore.paths import SCENE_DIR  # noqa: E402
from sphcore.scene import Scene, SceneError, describe_schema, shipped_scenes  # noqa: E402

MESHES = SCENE_DIR / "meshes"
SQUARE = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]


@pytest.fixture(autouse=True)
def cache(tmp_path_factory, monkeypatch):
    """A geometry cache of the test's own (SPHCORE_CACHE_DIR)."""
    folder = tmp_path_factory.mktemp("cache")
    monkeypatch.setenv("SPHCORE_CACHE_DIR", str(folder))
    return folder / "geometry"


def entry(dim=2, **keys):
    """A body table as Scene.from_dict leaves it (every key filled in)."""
    zero = 0.0 if dim == 2 else [0.0, 0.0, 0.0]
    return {"name": "b", "scale": 1.0, "rotate": zero, "translate": [0.0] * dim, "fluid": "outside", **keys}


def box_stl(path, lo, hi):
    """A closed box mesh from `lo` to `hi`, written to `path`."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    trimesh.creation.box(extents=hi - lo, transform=trimesh.transformations.translation_matrix((lo + hi) / 2)).export(path)
    return str(path)


def square_sd(points, centre, half, degrees):
    """Signed distance of `points` to a square of half-side `half` about `centre` rotated by `degrees`,
    positive inside (closed form: the box SDF in the square's frame)."""
    c, s = math.cos(math.radians(degrees)), math.sin(math.radians(degrees))
    p = (np.asarray(points, float) - centre) @ np.array([[c, -s], [s, c]])  # into the square's frame
    q = np.abs(p) - half
    outside = np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(1), 0.0)
    return -outside


def wendland(r, h):
    q = r / h
    return np.where(q < 1, (1 - q) ** 4 * (1 + 4 * q), 0.0)


# ---- signed distance ----

def test_signed_distance_of_unit_square():
    points = [[0.5, 0.5], [0.25, 0.5], [2.0, 0.5], [2.0, 2.0], [1.0, 0.5]]
    solid_inside = [-0.5, -0.25, 1.0, math.sqrt(2.0), 0.0]
    obstacle = geometry.load_body(0, entry(polygon=SQUARE))
    assert np.allclose(geometry.signed_distance(obstacle, points), solid_inside, atol=1e-12)
    container = geometry.load_body(0, entry(polygon=SQUARE, fluid="inside"))
    assert np.allclose(geometry.signed_distance(container, points), [-d for d in solid_inside], atol=1e-12)
    # scale, then rotate (about the origin), then translate: [0, 2]^2 -> [-2, 0] x [0, 2] -> [0, 2]^2
    moved = geometry.load_body(0, entry(polygon=SQUARE, scale=2.0, rotate=90.0, translate=[2.0, 0.0]))
    assert np.allclose(geometry.signed_distance(moved, [[1.0, 1.0], [3.0, 1.0]]), [-1.0, 1.0], atol=1e-12)


def test_signed_distance_of_unit_cube(tmp_path):
    mesh = box_stl(tmp_path / "cube.stl", [0, 0, 0], [1, 1, 1])
    points = [[0.5, 0.5, 0.5], [0.5, 0.5, 0.9], [2.0, 0.5, 0.5], [2.0, 2.0, 2.0], [1.5, 1.5, 0.5]]
    solid_inside = [-0.5, -0.1, 1.0, math.sqrt(3.0), math.sqrt(0.5)]
    obstacle = geometry.load_body(0, entry(3, mesh=mesh))
    assert np.allclose(geometry.signed_distance(obstacle, points), solid_inside, atol=1e-9)
    container = geometry.load_body(0, entry(3, mesh=mesh, fluid="inside"))
    assert np.allclose(geometry.signed_distance(container, points), [-d for d in solid_inside], atol=1e-9)


def test_rotations_about_x_then_y_then_z(tmp_path):
    """[0, 1] x [0, 2] x [0, 3] rotated 90 degrees about x, then 90 about y: (x, y, z) -> (x, -z, y) -> (y', ...)
    by hand: x in [0, 2], y in [-3, 0], z in [-1, 0] (the other order would give [0, 3] x [0, 1] x [0, 2])."""
    mesh = box_stl(tmp_path / "brick.stl", [0, 0, 0], [1, 2, 3])
    body = geometry.load_body(0, entry(3, mesh=mesh, rotate=[90.0, 90.0, 0.0], translate=[1.0, 0.0, 0.0]))
    lo, hi = body.bounds
    assert np.allclose(lo, [1, -3, -1], atol=1e-9) and np.allclose(hi, [3, 0, 0], atol=1e-9)


def test_lattice_distances_match_trimesh_everywhere():
    """The measured-near-the-surface path against trimesh's exact signed distance at every lattice point:
    equal within the band, the same side beyond it (the sign of each connected region)."""
    body = geometry.load_body(0, entry(3, mesh=str(MESHES / "wedge.stl"), rotate=[10.0, 20.0, 30.0],
                                       translate=[0.3, 0.2, 0.1], fluid="outside"))
    dx, band = 0.03, 0.06
    origin, counts = np.array([0.0, 0.0, 0.0]), np.array([36, 36, 36])
    lo, hi = geometry._region(body, origin, dx, counts, 0.3)
    points = geometry._lattice(origin, dx, counts, lo, hi)
    fast = geometry._region_distance(body, points, tuple(hi - lo), dx, band)
    exact = -trimesh.proximity.signed_distance(body.shape, points)  # (trimesh: positive inside; fluid outside)
    within = np.abs(exact) <= band
    assert within.sum() > 1000 and (~within).sum() > 1000
    assert np.allclose(fast[within], exact[within], atol=1e-9)
    assert (np.sign(fast[~within]) == np.sign(exact[~within])).all()
    far = np.abs(exact) > band + 6 * dx  # beyond band + 2 rho, rho = 3 sqrt(3) / 2 dx: in cells not measured
    assert far.sum() > 1000 and np.isinf(fast[far]).all()


# ---- wall particles and clipping ----

@pytest.mark.parametrize("degrees", [0.0, 30.0, 45.0])
def test_rotated_square_container_walls_and_fluid(degrees):
    """A square container (side 0.6 m about (0.5, 0.5)) rotated in a full block: the walls lie from depth h on the
    solid side to dx / 2 on the fluid side, every lattice point there is one, the fluid starts dx / 2 off the
    surface, and each fluid particle within h of the wall has the kernel sum of a full lattice."""
    dx, centre, half = 0.02, np.array([0.5, 0.5]), 0.3
    square = [[-half, -half], [half, -half], [half, half], [-half, half]]
    scene = Scene.from_dict({"fluid": {"spacing": dx, "blocks": [{"min": [0.0, 0.0], "max": [1.0, 1.0]}]},
                             "bodies": [{"name": "tank", "polygon": square, "rotate": degrees, "translate": [0.5, 0.5],
                                         "fluid": "inside"}]})
    h = scene.h
    x = scene.initial_positions().astype(float)
    w, owner = scene.wall_positions()
    w = w.astype(float)
    assert owner.dtype == np.int32 and (owner == 0).all()
    lattice = (np.stack(np.meshgrid(np.arange(50), np.arange(50), indexing="ij"), -1).reshape(-1, 2) + 0.5) * dx
    sd = square_sd(lattice, centre, half, degrees)
    tol = 1e-6  # m: float32 positions; a point this near dx / 2 counts as fluid (geometry.TOLERANCE)
    expected_walls = lattice[(sd >= -h - tol) & (sd < dx / 2 - tol)]
    assert sorted(map(tuple, np.round(w / dx - 0.5).astype(int))) == sorted(map(tuple, np.round(expected_walls / dx - 0.5)
                                                                                .astype(int)))
    assert (square_sd(w, centre, half, degrees) >= -h - tol).all()
    assert ((w > 0) & (w < 1)).all()
    fluid_sd = square_sd(x, centre, half, degrees)
    assert fluid_sd.min() >= dx / 2 - tol
    assert len(x) == (sd >= dx / 2 - tol).sum()  # none missing
    assert len(x) + len(w) == scene.particle_count() and len(x) == scene.fluid_count()
    grid = np.stack(np.meshgrid(*[np.arange(-10, 11) * dx] * 2), -1).reshape(-1, 2)
    full = wendland(np.linalg.norm(grid, axis=1), h).sum()
    everything = np.concatenate([x, w])
    for p in x[fluid_sd < h]:
        assert wendland(np.linalg.norm(everything - p, axis=1), h).sum() >= 0.95 * full, p


def test_walls_and_clipping_in_3d_match_trimesh(tmp_path):
    """A box obstacle rotated about z in a 3D box: the wall particles and the fluid kept against trimesh's exact
    signed distance at every point of the lattice."""
    mesh = box_stl(tmp_path / "block.stl", [-0.15, -0.1, -0.2], [0.15, 0.1, 0.2])
    dx = 0.05
    scene = Scene.from_dict({"physics": {"dimension": 3}, "fluid": {
        "spacing": dx, "smoothing_ratio": 2.0, "blocks": [{"min": [0.0, 0.0, 0.0], "max": [1.0, 0.6, 1.0]}]},
        "bodies": [{"name": "block", "mesh": str(tmp_path / "block.stl"), "rotate": [0.0, 0.0, 30.0],
                    "translate": [0.5, 0.3, 0.5]}]})
    assert mesh == scene["bodies"][0]["mesh"]
    h = scene.h
    lattice = (np.stack(np.meshgrid(*[np.arange(20)] * 3, indexing="ij"), -1).reshape(-1, 3) + 0.5) * dx
    sd = -trimesh.proximity.signed_distance(scene.bodies[0].shape, lattice)
    w, _ = scene.wall_positions()
    expected = lattice[(sd >= -h - 1e-6) & (sd < dx / 2 - 1e-6)]  # (STL vertices are float32)
    assert len(w) > 100
    assert sorted(map(tuple, np.round(w / dx - 0.5).astype(int))) == sorted(map(tuple, np.round(expected / dx - 0.5)
                                                                                .astype(int)))
    fluid = lattice[(lattice[:, 1] < 0.6) & (sd >= dx / 2 - 1e-6)]
    x = scene.initial_positions()
    assert len(x) == len(fluid) and len(x) < 20 * 12 * 20
    assert (-trimesh.proximity.signed_distance(scene.bodies[0].shape, x) >= dx / 2 - 1e-6).all()


def test_clipped_positions_start_hydrostatic():
    """hydrostatic_pressure and initial_density on a clipped block: rho_0 g (top - y) at every particle kept."""
    scene = Scene.from_dict({"fluid": {"spacing": 0.02, "blocks": [{"min": [0.0, 0.0], "max": [1.0, 0.5]}]},
                             "bodies": [{"name": "rock", "polygon": [[0.3, 0.0], [0.7, 0.0], [0.5, 0.3]]}]})
    x = scene.initial_positions()
    assert len(x) < 50 * 25
    p = scene.hydrostatic_pressure(x)
    assert np.allclose(p, 1000.0 * 9.81 * (0.5 - x[:, 1].astype(float)), rtol=1e-6)
    rho = scene.initial_density(x)
    assert rho.shape == (len(x),) and np.isfinite(rho).all() and (rho >= 1000.0).all()


def test_two_bodies_share_no_wall_particle():
    """Overlapping obstacles: a lattice point both claim is the first one's, once."""
    scene = Scene.from_dict({"fluid": {"spacing": 0.02, "blocks": [{"min": [0.0, 0.0], "max": [1.0, 0.3]}]},
                             "bodies": [{"name": "a", "polygon": [[0.2, 0.4], [0.6, 0.4], [0.6, 0.8], [0.2, 0.8]]},
                                        {"name": "b", "polygon": [[0.5, 0.4], [0.9, 0.4], [0.9, 0.8], [0.5, 0.8]]}]})
    w, owner = scene.wall_positions()
    keys = np.round(w.astype(float) / 0.02 - 0.5).astype(int)
    assert len(np.unique(keys, axis=0)) == len(w)
    assert set(owner.tolist()) == {0, 1} and (np.diff(owner) >= 0).all()  # body by body
    assert [b.name for b in scene.bodies] == ["a", "b"] and np.allclose(scene.bodies[0].centroid, [0.4, 0.6])


def test_precision_of_wall_positions():
    data = {"physics": {"precision": "float64"}, "fluid": {"spacing": 0.02},
            "bodies": [{"name": "rock", "polygon": [[0.5, 0.0], [0.9, 0.0], [0.7, 0.4]]}]}
    assert Scene.from_dict(data).wall_positions()[0].dtype == np.float64
    data["physics"]["precision"] = "float32"
    assert Scene.from_dict(data).wall_positions()[0].dtype == np.float32
    empty = Scene.from_dict({"fluid": {"spacing": 0.02}}).wall_positions()
    assert empty[0].shape == (0, 2) and empty[1].dtype == np.int32


# ---- cache ----

def test_cache_hit_gives_the_same_walls_faster(cache):
    body = geometry.load_body(0, entry(3, mesh=str(MESHES / "cylinder_tank.stl"), fluid="inside",
                                       translate=[0.35, 0.05, 0.35]))
    args = ([0.0, 0.0, 0.0], [0.7, 0.7, 0.7], 0.015, 0.03)
    start = time.perf_counter()
    cold = geometry.wall_particles([body], *args)
    t_cold = time.perf_counter() - start
    start = time.perf_counter()
    warm = geometry.wall_particles([body], *args)
    t_warm = time.perf_counter() - start
    assert len(cold[0]) > 10000
    assert np.array_equal(cold[0], warm[0]) and np.array_equal(cold[1], warm[1])
    assert t_warm < t_cold / 5, (t_cold, t_warm)
    (entry_file,) = cache.glob("walls-*.npz")
    entry_file.write_bytes(b"not a zip file")  # damaged: computed again, with a warning
    with pytest.warns(CacheWarning, match="unreadable"):
        again = geometry.wall_particles([body], *args)
    assert np.array_equal(cold[0], again[0])
    other = geometry.load_body(0, entry(3, mesh=str(MESHES / "cylinder_tank.stl"), fluid="inside",
                                        translate=[0.35, 0.06, 0.35]))
    geometry.wall_particles([other], *args)
    assert len(list(cache.glob("walls-*.npz"))) == 2  # the transform is part of the key


# ---- scenes ----

def test_polygon_scene_round_trip(tmp_path):
    (tmp_path / "rock.toml").write_text("""
[fluid]
spacing = 0.02
blocks = [{ min = [0.0, 0.0], max = [1.0, 0.4] }]

[[bodies]]
name = "rock"
polygon = [[0.3, 0.0], [0.7, 0.0], [0.5, 0.3]]
rotate = 10
""")
    scene = Scene.load(tmp_path / "rock.toml")
    again = Scene.from_dict(json.loads(scene.to_json()))
    assert again.config == scene.config
    assert np.array_equal(again.initial_positions(), scene.initial_positions())
    assert np.array_equal(again.wall_positions()[0], scene.wall_positions()[0]) and len(scene.wall_positions()[0])


def test_mesh_scene_round_trip_from_another_folder(tmp_path, monkeypatch):
    (tmp_path / "meshes").mkdir()
    box_stl(tmp_path / "meshes" / "box.stl", [0.3, 0.0, 0.3], [0.6, 0.3, 0.6])
    (tmp_path / "scene.toml").write_text("""
[physics]
dimension = 3

[fluid]
spacing = 0.05
smoothing_ratio = 2.0
blocks = [{ min = [0.0, 0.0, 0.0], max = [1.0, 0.5, 1.0] }]

[[bodies]]
name = "box"
mesh = "meshes/box.stl"
""")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    scene = Scene.load(tmp_path / "scene.toml")
    assert scene["bodies"][0]["mesh"] == str(tmp_path / "meshes" / "box.stl")
    again = Scene.from_dict(json.loads(scene.to_json()))  # scene.json, as resume reads it
    assert np.array_equal(again.wall_positions()[0], scene.wall_positions()[0])
    assert len(scene.initial_positions()) == 20 * 10 * 20 - 6 * 6 * 6  # the box's lattice points cut out
    monkeypatch.chdir(tmp_path)  # a dict's relative path: from the working folder
    relative = Scene.from_dict({**json.loads(scene.to_json()), "bodies": [{"name": "box", "mesh": "meshes/box.stl"}]})
    assert relative.config == scene.config


def test_shipped_meshes():
    """Closed, small, and the SPHERIC box where the shipped scene's box obstacle is."""
    for name in ("spheric_box", "cylinder_tank", "wedge", "cylinder_pier"):
        path = MESHES / f"{name}.stl"
        assert path.stat().st_size < 200_000, name
        mesh = trimesh.load(path)
        assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0, name
    box = tomllib.loads((SCENE_DIR / "spheric_test2.toml").read_text())["domain"]["obstacles"][0]
    mesh = trimesh.load(MESHES / "spheric_box.stl")
    assert np.allclose(mesh.bounds, [box["min"], box["max"]], atol=1e-6)
    tank = trimesh.load(MESHES / "cylinder_tank.stl")
    assert 0.99 * math.pi * 0.09 * 0.6 < tank.volume <= math.pi * 0.09 * 0.6  # an inscribed 48-gon
    assert np.allclose(tank.bounds, [[-0.3, 0.0, -0.3], [0.3, 0.6, 0.3]], atol=1e-6)


def test_shipped_scene_with_a_mesh():
    """dam_break_obstacle_3d: the pier stands where its comments say, clear of the column, and its gauges sit
    where they say: the pressure on the pier's face toward the water, the height in front of it, in the fluid."""
    scene = Scene.load("dam_break_obstacle_3d")
    pier = trimesh.load(MESHES / "cylinder_pier.stl")
    assert 0.99 * math.pi * 0.045**2 * 0.3 < pier.volume <= math.pi * 0.045**2 * 0.3  # an inscribed 32-gon
    pier.apply_translation(scene["bodies"][0]["translate"])
    assert np.allclose(pier.bounds, [[0.555, 0.0, 0.105], [0.645, 0.3, 0.195]], atol=1e-6)
    fluid = scene.initial_positions()
    assert len(fluid) == 20 * 20 * 20 and fluid[:, 0].max() < 0.3  # the whole column, untouched by the clipping
    walls, body = scene.wall_positions()
    assert len(walls) > 0 and np.all(body == 0)
    assert np.all(np.abs(walls[:, [0, 2]].mean(axis=0) - [0.6, 0.15]) < 1e-6)  # symmetric about the pier's axis
    gauges = {g["name"]: g for g in scene["gauges"]}
    assert [gauges[n]["quantity"] for n in ("p_pier", "h_front", "f_pier")] == ["pressure", "height", "force"]
    assert abs(trimesh.proximity.signed_distance(pier, [gauges["p_pier"]["at"]])[0]) < 1e-6  # on the face
    assert gauges["p_pier"]["at"][0] < 0.6  # on the side toward the water (x < the axis)
    assert 0.3 < gauges["h_front"]["at"][0] < 0.555 and gauges["h_front"]["at"][2] == 0.15
    assert gauges["f_pier"]["body"] == "pier"


def test_every_shipped_scene_loads():
    names = shipped_scenes()
    assert {"dam_break_3d", "dam_break_obstacle_3d", "spheric_test2"} <= set(names)
    for name in names:
        assert Scene.load(name)["name"] == name


def test_sphcore_keys_lists_bodies():
    lines = [line for line in describe_schema() if line.startswith("bodies ")]
    assert len(lines) == 1 and "polygon" in lines[0] and "mesh" in lines[0] and "fluid" in lines[0]


# ---- refusals ----

BASE2 = {"fluid": {"spacing": 0.02, "blocks": [{"min": [0.0, 0.0], "max": [1.0, 0.4]}]}}
BASE3 = {"physics": {"dimension": 3},
         "fluid": {"spacing": 0.05, "smoothing_ratio": 2.0, "blocks": [{"min": [0.0, 0.0, 0.0], "max": [1.0, 0.4, 1.0]}]}}
ROCK = [[0.3, 0.5], [0.7, 0.5], [0.5, 0.8]]


def scene_with(base, *bodies, **tables):
    data = json.loads(json.dumps(base))
    for table, keys in tables.items():
        data.setdefault(table, {}).update(keys)
    return {**data, "bodies": list(bodies)}


@pytest.mark.parametrize("bodies, tables, match", [
    ([{"name": "p", "polygon": [[0.0, 0.0], [1.0, 0.0]]}], {},
     r'^bodies\[0\] \("p"\)\.polygon: expected at least 3 vertices'),
    ([{"name": "p", "polygon": [[0.2, 0.5], [0.6, 0.9], [0.6, 0.5], [0.2, 0.9]]}], {},
     r'^bodies\[0\] \("p"\): the polygon is not a simple closed polygon \(Self-intersection'),
    ([{"name": "p", "polygon": ROCK, "mesh": "a.stl"}], {}, r'^bodies\[0\] \("p"\): give exactly one of .* not both'),
    ([{"name": "p"}], {}, r'^bodies\[0\] \("p"\): give exactly one of .* not neither'),
    ([{"name": "p", "mesh": "a.stl"}], {}, r'^bodies\[0\] \("p"\): a mesh in a 2D scene; give polygon'),
    ([{"name": "p", "polygon": ROCK}, {"name": "p", "polygon": ROCK}], {},
     r'^bodies\[1\] \("p"\): the name is also bodies\[0\]\'s'),
    ([{"polygon": ROCK}], {}, r"^bodies\[0\]: give it a name"),
    ([{"name": "p", "polygon": ROCK, "colour": "red"}], {}, r"^bodies\[0\] \(\"p\"\): unknown key 'colour'"),
    ([{"name": "p", "polygon": ROCK, "rotate": [0, 0, 30]}], {}, r'^bodies\[0\] \("p"\)\.rotate = .*: give one angle'),
    ([{"name": "p", "polygon": ROCK, "fluid": "beside"}], {}, r'^bodies\[0\] \("p"\)\.fluid = \'beside\': choose one'),
    ([{"name": "p", "polygon": ROCK, "scale": 0.0}], {}, r'^bodies\[0\] \("p"\)\.scale = 0.0: must be within'),
    ([{"name": "plate", "polygon": [[0.2, 0.6], [0.8, 0.6], [0.8, 0.62], [0.2, 0.62]]}], {},
     r'^bodies\[0\] \("plate"\): thinner than the wall layer: .* less than h / 2 = 0.04 m'),
    ([{"name": "far", "polygon": [[2.0, 2.0], [2.5, 2.0], [2.2, 2.5]]}], {},
     r'^bodies\[0\] \("far"\): outside the box domain\.box_min \.\. domain\.box_max'),
    ([{"name": "tank", "polygon": [[-0.1, -0.1], [1.1, -0.1], [1.1, 0.9], [-0.1, 0.9]], "fluid": "inside"}], {},
     r'^bodies\[0\] \("tank"\): a container whose inside .* reaches out of the box'),
    ([{"name": "lid", "polygon": [[0.0, 0.0], [1.0, 0.0], [1.0, 0.5], [0.0, 0.5]]}], {},
     r"^fluid\.blocks\[0\] = .*: no particle left after clipping"),
    ([{"name": "p", "polygon": ROCK}], {"physics": {"model": "dfsph"}},
     r'^bodies\[0\] \("p"\): bodies need physics\.pressure_solver = "state_equation"'),
    ([{"name": "p", "polygon": ROCK}], {"domain": {"boundary": "open"}},
     r'^bodies\[0\] \("p"\): bodies need domain\.boundary = "walls"'),
])
def test_refusals_2d(bodies, tables, match):
    with pytest.raises(SceneError, match=match):
        Scene.from_dict(scene_with(BASE2, *bodies, **tables))


def test_thick_enough_is_accepted():
    """A plate 1.2 h thick passes the test a plate 0.25 h thick fails (test_refusals_2d)."""
    scene = Scene.from_dict(scene_with(BASE2, {"name": "plate", "polygon": [[0.2, 0.6], [0.8, 0.6], [0.8, 0.696],
                                                                           [0.2, 0.696]]}))
    assert len(scene.wall_positions()[0]) > 0


def test_refusals_3d(tmp_path):
    def refused(match, **body):
        with pytest.raises(SceneError, match=match):
            Scene.from_dict(scene_with(BASE3, {"name": "m", **body}))

    refused(r'^bodies\[0\] \("m"\): mesh .*nope\.stl: no such file', mesh=str(tmp_path / "nope.stl"))
    (tmp_path / "junk.stl").write_bytes(bytes(range(256)) * 3)
    refused(r'^bodies\[0\] \("m"\): mesh .*junk\.stl: no triangles read', mesh=str(tmp_path / "junk.stl"))
    (tmp_path / "mesh.txt").write_text("v 0 0 0\n")
    refused(r'^bodies\[0\] \("m"\): mesh .*mesh\.txt: not an STL, OBJ or PLY file', mesh=str(tmp_path / "mesh.txt"))
    box = trimesh.creation.box(extents=[0.3, 0.3, 0.3], transform=trimesh.transformations.translation_matrix([0.5] * 3))
    trimesh.Trimesh(box.vertices, box.faces[1:]).export(tmp_path / "open.stl")
    refused(r'^bodies\[0\] \("m"\): mesh .*open\.stl is not closed: 3 open edges', mesh=str(tmp_path / "open.stl"))
    refused(r'^bodies\[0\] \("m"\): a polygon in a 3D scene; give mesh', polygon=ROCK)
    box_stl(tmp_path / "sheet.stl", [0.2, 0.6, 0.2], [0.8, 0.62, 0.8])
    refused(r'^bodies\[0\] \("m"\): thinner than the wall layer', mesh=str(tmp_path / "sheet.stl"))
    box_stl(tmp_path / "away.stl", [2.0, 2.0, 2.0], [2.5, 2.5, 2.5])
    refused(r'^bodies\[0\] \("m"\): outside the box', mesh=str(tmp_path / "away.stl"))
    refused(r'^bodies\[0\] \("m"\)\.translate = \[0\.0, 0\.0\] has 2 components', mesh=str(tmp_path / "away.stl"),
            translate=[0.0, 0.0])


def test_scene_load_names_the_file_and_the_body(tmp_path):
    (tmp_path / "s.toml").write_text('[[bodies]]\nname = "tank"\nmesh = "tank.stl"\n')
    with pytest.raises(SceneError, match=r's\.toml: bodies\[0\] \("tank"\): a mesh in a 2D scene'):
        Scene.load(tmp_path / "s.toml")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert Scene.load("dam_break_2d")["bodies"] == []
