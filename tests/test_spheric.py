"""Box obstacles (domain.obstacles) and SPHERIC test 2: the scene key's errors, particles thrown
at a box never end inside it (both backends), the two backends agree stage by stage on a scene
with a box, a box's face mirrors like a wall, the height gauges and pressure sensors on known
fields, and a very coarse run of the benchmark through `sphcore validate spheric`.

Every simulated scene here has the benchmark's specialization constants (3D, grid, walls, Tait,
viscosity, gravity, one obstacle), so numba compiles the mirrors once for the whole file."""
import csv
import json
import math

import numpy as np
import pytest
from conftest import BACKENDS, assert_stage_agrees, particles

from sphcore.backends import Stage, empty_state, make_backend, plan
from sphcore.params import MAX_OBSTACLES
from sphcore.scene import Scene, SceneError
from sphcore.validate import spheric

BOX = {"min": [0.15, 0.0, 0.1], "max": [0.25, 0.15, 0.3]}


def tank(obstacles=None, blocks=None, spacing=0.02, **fluid):
    """A 0.4 m tank with `obstacles`, Tait, viscosity and gravity: the benchmark's constants."""
    return Scene.from_dict({
        "physics": {"model": "graphics", "dimension": 3, "equation_of_state": "tait"},
        "domain": {"box_min": [0.0, 0.0, 0.0], "box_max": [0.4, 0.4, 0.4], "obstacles": [BOX] if obstacles is None else obstacles},
        "fluid": {"spacing": spacing, "blocks": blocks or [{"min": [0.0, 0.0, 0.0], "max": [0.1, 0.1, 0.1]}],
                  "stiffness": 400.0, "viscosity": 0.5, **fluid},
        "forces": {"gravity": [0.0, -9.81, 0.0]},
        "time": {"dt": 2e-4},
    })


def state_of(scene, x, v=None):
    """(params, state) of particles at x (N, 3) with velocities v, the scene's obstacles filled in."""
    params = scene.params(len(x))
    state = empty_state(params, "float32", scene["domain.obstacles"])
    state["particle_x"][:, :3] = x
    if v is not None:
        state["particle_v"][:, :3] = v
    return params, state


def inside(x, box=BOX):
    """Particles strictly inside `box` (on a face is outside; the faces in float32, as the shaders see them)."""
    return ((x > np.float32(box["min"])) & (x < np.float32(box["max"]))).all(axis=1)


# ---------------------------------------------------------------------------------- the scene key

@pytest.mark.parametrize("obstacles, message", [
    ([{"min": [0.3, 0.0, 0.1], "max": [0.5, 0.1, 0.2]}], r"domain.obstacles\[0\].*not inside the box"),
    ([{"min": [0.3, 0.0], "max": [0.35, 0.1]}], r"domain.obstacles\[0\].min = .* has 2 components"),
    ([{"min": [0.3, 0.1, 0.1], "max": [0.2, 0.2, 0.2]}], r"domain.obstacles\[0\]: min .* below max"),
    ([{"min": [0.3, 0.0, 0.1]}], r"domain.obstacles\[0\]: expected a table with exactly the keys min and max"),
    ([BOX] * (MAX_OBSTACLES + 1), rf"domain.obstacles: {MAX_OBSTACLES + 1} boxes, at most {MAX_OBSTACLES}"),
    ("box", r"domain.obstacles: expected a list"),
    ([{"min": [0.05, 0.05, 0.05], "max": [0.2, 0.2, 0.2]}],
     r"fluid.blocks\[0\] = .*particles would start inside domain.obstacles\[0\]"),
])
def test_bad_obstacles_are_one_line_errors_naming_the_key(obstacles, message):
    with pytest.raises(SceneError, match=message) as e:
        tank(obstacles)
    assert "\n" not in str(e.value)


def test_obstacles_default_to_none_and_set_the_constant():
    assert tank([]).spec.OBSTACLES == 0
    assert tank([BOX, BOX]).spec.OBSTACLES == 2
    # a block that touches a face, without a particle inside, is allowed
    tank(blocks=[{"min": [0.0, 0.0, 0.0], "max": [0.15, 0.1, 0.1]}])


def test_a_state_without_the_scenes_obstacles_is_refused():
    scene = tank()
    x = scene.initial_positions()
    params = scene.params(len(x))
    with pytest.raises(ValueError, match="pass the scene's domain.obstacles"):
        make_backend("numba", params, empty_state(params), plan(scene), scene.spec)


# ------------------------------------------------------------------------------------ the boundary

AIMED = 3  # the last particles of thrown_particles, aimed at edges and a corner


def thrown_particles():
    """(x, v): particles thrown head-on at each side face of BOX at 1-4 m/s, dropped onto its top,
    one sliding on the floor into its face (the box stands on the floor: nothing may pass under
    it), and AIMED at two of its edges and a corner."""
    rng = np.random.default_rng(5)
    lo, hi = np.array(BOX["min"]), np.array(BOX["max"])
    x, v = [[lo[0] - 0.05, 0.0, 0.2]], [[3.0, 0.0, 0.0]]
    for axis, side in ((0, -1), (0, 1), (2, -1), (2, 1), (1, 1)):
        for _ in range(6):
            p = rng.uniform(lo + 0.01, hi - 0.01)
            p[axis] = lo[axis] - 0.05 if side < 0 else hi[axis] + 0.05
            u = np.zeros(3)
            u[axis] = -side * rng.uniform(1.0, 4.0)
            x.append(p)
            v.append(u)
    for target, offset in (([lo[0], hi[1], 0.2], [-0.04, 0.04, 0.0]), ([lo[0], 0.05, lo[2]], [-0.04, 0.0, -0.04]),
                           (hi, [0.04, 0.04, 0.04])):
        x.append(np.add(target, offset))
        v.append(np.multiply(offset, -60.0))
    return np.array(x, np.float32), np.array(v, np.float32)


@pytest.mark.parametrize("backend", BACKENDS)
def test_particles_thrown_at_a_box_never_end_inside_it(open_backend, backend):
    scene = tank(blocks=[{"min": [0.0, 0.3, 0.0], "max": [0.02, 0.32, 0.02]}])
    x0, v0 = thrown_particles()
    params, state = state_of(scene, x0, v0)
    sim = open_backend(backend, params, state, plan(scene), scene.spec)
    lo, hi = np.array(BOX["min"]), np.array(BOX["max"])
    head_on = len(x0) - AIMED
    for _ in range(10):  # 0.1 s: every particle reaches the box within 0.05 s
        sim.step(50)
        x = particles(sim, 3)["particle_x"]
        assert np.isfinite(x).all()
        assert not inside(x).any(), f"{backend}: particles {np.flatnonzero(inside(x))} inside the box"
        # stopped at the face they were thrown at: never past it along their flight
        for k in range(head_on):
            axis = int(np.flatnonzero(v0[k])[0])
            face = lo[axis] if v0[k, axis] > 0 else hi[axis]
            assert (x[k, axis] - face) * np.sign(v0[k, axis]) <= 1e-6, f"{backend}: particle {k} went through"
    assert (particles(sim, 3)["particle_v"][:head_on] * v0[:head_on] < 0).any(axis=1).mean() > 0.5


@pytest.mark.parametrize("backend", BACKENDS)
def test_2d_a_particle_that_ends_a_step_in_a_box_is_put_onto_its_nearest_face(open_backend, backend):
    """integrate alone, in 2D, on a box standing on the floor: the nearest face (never the floor,
    which the box continues through), the normal speed reversed and scaled by the restitution."""
    scene = Scene.from_dict({
        "physics": {"model": "graphics", "gravity": False}, "walls": {"restitution": 0.5}, "time": {"dt": 1e-3},
        "domain": {"box_min": [0.0, 0.0], "box_max": [0.5, 0.5], "obstacles": [{"min": [0.2, 0.0], "max": [0.3, 0.1]}]},
        "fluid": {"blocks": [{"min": [0.0, 0.2], "max": [0.1, 0.3]}]}})
    end = np.array([[0.21, 0.05], [0.29, 0.05], [0.25, 0.09], [0.24, 0.005], [0.205, 0.094], [0.1, 0.05]])
    v = np.array([[1.0, 0.0], [-1.0, 0.0], [0.0, -1.0], [0.0, 1.0], [1.0, -1.0], [1.0, 0.0]])
    params = scene.params(len(end))
    state = empty_state(params, "float32", scene["domain.obstacles"])
    state["particle_x"][:, :2] = end - 1e-3 * v
    state["particle_v"][:, :2] = v
    sim = open_backend(backend, params, state, [Stage("integrate")], scene.spec)
    sim.run_stage("integrate")
    out = particles(sim, 2)
    lo, hi = np.float32(0.2), np.float32(0.3)
    expected_x = [[lo, 0.05], [hi, 0.05], [0.25, np.float32(0.1)], [lo, 0.005], [lo, 0.094], [0.1, 0.05]]
    expected_v = [[-0.5, 0.0], [0.5, 0.0], [0.0, 0.5], [0.0, 1.0], [-0.5, -1.0], [1.0, 0.0]]
    assert np.allclose(out["particle_x"], expected_x, atol=1e-6, rtol=0)
    assert np.array_equal(out["particle_x"][[0, 3, 4], 0], [lo, lo, lo])  # exactly on the face
    assert np.allclose(out["particle_v"], expected_v, atol=1e-6, rtol=0)


def test_a_box_face_mirrors_like_a_wall():
    """Fluid between the wall x = 0 and a box filling the tank beyond x = 0.1: the density is
    symmetric about x = 0.05, so the box's face gives the particles at it the wall's images."""
    box = {"min": [0.1, 0.0, 0.0], "max": [0.4, 0.4, 0.4]}
    scene = tank([box], blocks=[{"min": [0.0, 0.0, 0.0], "max": [0.1, 0.1, 0.1]}])
    x = scene.initial_positions()
    params, state = state_of(scene, x)
    backend = make_backend("numba", params, state, plan(scene), scene.spec)
    for stage in plan(scene)[:-2]:  # the sort, then compute_density
        backend.run_stage(stage)
    rho = particles(backend, 3)["particle_rho"]
    mirror = np.lexsort((x[:, 2], x[:, 1], np.round(0.1 - x[:, 0], 6)))
    order = np.lexsort((x[:, 2], x[:, 1], np.round(x[:, 0], 6)))
    assert np.allclose(rho[order], rho[mirror], rtol=1e-5)
    # and the particles at the face have the interior's density, not a free surface's
    at_face, middle = np.isclose(x[:, 0], 0.09), np.isclose(x[:, 0], 0.05)
    assert rho[at_face].mean() > 0.97 * rho[middle].mean()


# Same tolerances and reasons as tests/test_backends.py: one dispatch, sums in the same order in
# float32, a GPU may fuse a * b + c: within 1e-5 of each buffer's largest magnitude.
STAGE_RTOL = 1e-5


def test_backends_agree_stage_by_stage_on_a_box(open_backend):
    """A jittered block against the box's face and top, a few particles inside it (integrate must
    push them out) and on its faces: every stage on both backends."""
    scene = tank(blocks=[{"min": [0.05, 0.0, 0.12], "max": [0.15, 0.24, 0.24]}])
    rng = np.random.default_rng(7)
    x = scene.initial_positions() + rng.uniform(-0.3, 0.3, (len(scene.initial_positions()), 3)).astype(np.float32) * 0.02
    x = np.vstack([x, [[0.16, 0.05, 0.2], [0.2, 0.14, 0.15], [0.15, 0.1, 0.2], [0.2, 0.15, 0.2]]]).astype(np.float32)
    x = np.clip(x, 0.0, 0.4)
    params, state = state_of(scene, x, rng.normal(0.0, 1.0, x.shape))
    stages = plan(scene)
    cpu = open_backend("numba", params, state, stages, scene.spec)
    gpu = open_backend("vulkan", params, state, stages, scene.spec)
    for stage in stages:
        cpu.run_stage(stage)
        gpu.run_stage(stage)
        a, b = cpu.read(), gpu.read()
        assert_stage_agrees(a, b, stage, STAGE_RTOL)
    assert not inside(particles(cpu, 3)["particle_x"]).any()
    cpu.step(20)
    gpu.step(20)
    gap = np.abs(particles(cpu, 3)["particle_x"] - particles(gpu, 3)["particle_x"]).max()
    assert gap <= 1e-3 * scene["fluid.spacing"], f"positions differ by {gap:g} m after 20 steps"


# -------------------------------------------------------------------------------------- the probes

def resting_layer(depth, dx=0.04):
    """Particles at the cell centres of a lattice filling the tank to `depth`, the box left out."""
    axes = [np.arange(int(round(w / dx))) * dx + dx / 2 for w in (spheric.TANK[0], depth, spheric.TANK[2])]
    x = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    box = {"min": spheric.BOX_MIN, "max": spheric.BOX_MAX}
    return x[~(((x > np.array(box["min"])) & (x < np.array(box["max"]))).all(axis=1))]


@pytest.mark.parametrize("depth", [0.12, 0.4, 0.56])
def test_gauges_read_the_depth_of_a_resting_layer_within_dx(depth):
    dx = 0.04
    heights = spheric.water_heights(resting_layer(depth, dx), dx, 2 * dx)
    for name, height in heights.items():
        assert abs(height - depth) < dx, f"{name}: {height:.4f} m for a {depth} m layer"
    assert spheric.water_heights(np.zeros((0, 3)), dx, 2 * dx) == {name: 0.0 for name in spheric.GAUGES}


def test_sensors_read_hydrostatic_pressure():
    """p = rho g (D - y) on every particle: each sensor reads rho g (D - y_sensor) within
    rho g h / 2, the most by which the floor or the box's top can shift the mean depth of the
    particles within h of a sensor (Shepard's average of a linear field is exact otherwise)."""
    dx, depth = 0.02, 0.4
    x = resting_layer(depth, dx)
    p = 1000.0 * 9.81 * (depth - x[:, 1])
    read = spheric.pressures(x, p, 2 * dx)
    for name, (_, y, _) in spheric.SENSORS.items():
        assert abs(read[name] - 1000.0 * 9.81 * (depth - y)) <= 1000.0 * 9.81 * dx, f"{name}: {read[name]:.0f} Pa"
    dry = spheric.pressures(x[x[:, 0] > 1.5], p[x[:, 0] > 1.5], 2 * dx)
    assert dry == {name: 0.0 for name in spheric.SENSORS}


def test_running_mean_keeps_a_ramp_and_removes_a_saw_tooth():
    t = np.arange(0.0, 2.0, 0.01)
    ramp = spheric.running_mean(t, 3.0 * t)
    inner = (t > 0.1) & (t < 1.9)
    assert np.allclose(ramp[inner], 3.0 * t[inner])
    assert np.allclose(spheric.running_mean(t, np.where(np.arange(len(t)) % 2, 1.0, -1.0))[inner], 0.0, atol=0.1)


def test_the_scene_file_is_the_validation_scene():
    from sphcore.cli import scene_path
    given, built = Scene.load(scene_path("spheric_test2")), spheric.spheric_scene()
    for key in ("domain.box_min", "domain.box_max", "forces.gravity", "physics.equation_of_state", "fluid.spacing",
                "fluid.smoothing_ratio", "fluid.stiffness", "fluid.viscosity", "time.dt", "time.dt_fraction"):
        assert given[key] == pytest.approx(built[key]) if key != "physics.equation_of_state" else given[key] == built[key]
    for a, b in ((given["domain.obstacles"], built["domain.obstacles"]), (given["fluid.blocks"], built["fluid.blocks"])):
        assert len(a) == len(b) == 1 and a[0]["min"] == pytest.approx(b[0]["min"]) and a[0]["max"] == pytest.approx(b[0]["max"])
    assert len(given.initial_positions()) == 61 * 28 * 50
    assert given["time.steps"] * given.dt == pytest.approx(6.0, abs=0.01)


def test_the_measured_height_columns_are_mapped_by_arrival():
    """The file's height columns hold H3, H2, H1, H4: mapped so, the gauges nearer the gate are
    wetted first, and H4 (in the reservoir) starts at the column's 0.55 m."""
    t, exp = spheric.read_experiment()
    wet = {name: t[np.argmax(exp[name] > 0.01)] for name in ("H1", "H2", "H3")}
    assert wet["H3"] < wet["H2"] < wet["H1"]
    assert abs(exp["H4"][0] - 0.55) < 0.01
    assert all(abs(exp[name][0]) < 0.005 for name in ("H1", "H2", "H3"))


# ----------------------------------------------------------------------------- a very coarse run

@pytest.fixture(scope="module")
def coarse_run(tmp_path_factory):
    from sphcore.cli import main
    out = tmp_path_factory.mktemp("spheric")
    assert main(["validate", "spheric", "--out", str(out), "--spacing", "0.08", "--t-end", "0.3"]) in (0, None)
    with (out / "spheric_test2.csv").open() as f:
        rows = [{k: float(v) for k, v in r.items()} for r in csv.DictReader(f)]
    return rows, json.loads((out / "spheric_test2.json").read_text()), out


def test_coarse_run_writes_its_series_summary_and_plot(coarse_run):
    rows, summary, out = coarse_run
    assert list(rows[0]) == ["t", "H1", "H2", "H3", "H4"] + [f"P{k}" for k in range(1, 9)]
    assert (out / "spheric_test2.png").stat().st_size > 10_000
    assert summary["particles"] == 15 * 7 * 12 and summary["device"] == "cpu"
    assert summary["settings"]["spacing"] == 0.08 and summary["rms_until_s"] == pytest.approx(0.3, abs=0.01)
    assert all(math.isfinite(summary[f"rms_{name}"]) for name in list(spheric.GAUGES) + list(spheric.SENSORS))
    t = np.array([r["t"] for r in rows])
    assert np.all(np.diff(t) > 0) and np.diff(t).max() <= spheric.SAMPLE_DT * 1.2


def test_coarse_run_at_0_3_s_follows_the_physics(coarse_run):
    """0.3 s after release (experiment: H4 0.49 m, H3 0.07 m, H2 and H1 dry, the front 0.3 m
    short of the box): the reservoir drains, the surge has passed H3 but not H2, no sensor on the
    box is wet."""
    rows, summary, _ = coarse_run
    H4 = np.array([r["H4"] for r in rows])
    assert abs(H4[0] - 0.55) <= 0.08  # the column, to the coarse lattice's dx
    assert np.all(np.diff(H4) < 0.005)  # it only drains
    assert 0.40 < H4[-1] < H4[0] - 0.05
    assert rows[-1]["H3"] > 0.02 and rows[-1]["H2"] == 0.0 and rows[-1]["H1"] == 0.0
    assert all(r[f"P{k}"] == 0.0 for r in rows for k in range(1, 9))
    assert summary["rms_H4"] < 0.03 and summary["rms_H3"] < 0.03
