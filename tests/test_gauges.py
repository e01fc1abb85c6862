"""Gauges declared in the scene ([[gauges]]; sphcore/gauges.py, shaders/sph/sample_gauges.comp): a tank at rest
reads its hydrostatic pressure, its depth and no velocity; both backends write the same CSV bytes; a resumed run
the rows of one never stopped; a body's force and moment reduce to the same bits on both backends, every run;
bad gauges are refused in one line."""
import shutil

import numpy as np
import pytest

import sphcore
from sphcore.backends import empty_state, plan
from sphcore.errors import SceneError
from sphcore.gauges import GAUGE_SLOTS, columns, read_csv, table
from sphcore.scene import Scene

from conftest import VALIDATION, vulkan_or_skip

DX, DEPTH, WIDTH = 0.02, 0.2, 0.4
AT_P = [0.2, 0.03]  # near the bottom
G = 9.81


def tank(**time):
    """A 2D tank at rest (engineering model: continuity density starting hydrostatic), 200 particles, with a gauge
    of every point quantity, one in the air."""
    return Scene.from_dict({
        "name": "tank", "physics": {"model": "engineering"},
        "domain": {"box_min": [0.0, 0.0], "box_max": [WIDTH, WIDTH]},
        "fluid": {"spacing": DX, "blocks": [{"min": [0.0, 0.0], "max": [WIDTH, DEPTH]}]},
        "time": {"steps": 300, "output_every": 100, "checkpoint_every": 150, **time},
        "gauges": [{"name": "p_bottom", "quantity": "pressure", "at": AT_P, "interval": 0.01},
                   {"name": "v_mid", "quantity": "velocity", "at": [0.2, 0.1], "interval": 0.01},
                   {"name": "rho_mid", "quantity": "density", "at": [0.2, 0.1], "interval": 0.02},
                   {"name": "level", "quantity": "height", "at": [0.2, 0.0], "interval": 0.01},
                   {"name": "p_air", "quantity": "pressure", "at": [0.2, 0.35], "interval": 0.05}]})


def options(backend):
    if backend == "vulkan":
        vulkan_or_skip()
        return {"validation": VALIDATION}
    return {}


RUNS = {}  # backend -> the tank's run folder


@pytest.fixture(scope="module", params=["numba", "vulkan"])
def tank_run(request, tmp_path_factory):
    out = tmp_path_factory.mktemp(f"tank_{request.param}")
    final = sphcore.run(tank(), backend=request.param, out_dir=out, progress=False, **options(request.param))
    RUNS[request.param] = out
    return request.param, out, final


def test_a_tank_at_rest_reads_its_pressure_depth_and_no_velocity(tank_run):
    _, out, final = tank_run
    header, p = read_csv(out / "gauges" / "p_bottom.csv")
    assert header == ["time [s]", "p [Pa]"]
    # a sample at the first step at or past each multiple of 0.01 s, from t = 0 to the run's end
    multiple = np.floor(p[:, 0] / 0.01 + 1e-5)
    assert p[0, 0] == 0.0 and (np.diff(p[:, 0]) > 0).all() and (np.diff(multiple) == 1).all()  # one a multiple
    assert np.floor(final["time"] / 0.01) - multiple[-1] <= 1 and len(p) > 25  # (the last step's state: unsampled)
    settled = p[:, 0] >= 0.1
    expected = 1000.0 * G * (DEPTH - AT_P[1])
    assert np.abs(p[settled, 1] / expected - 1).max() < 0.03, (p[settled, 1], expected)
    header, h = read_csv(out / "gauges" / "level.csv")
    assert header == ["time [s]", "height [m]"]
    assert np.abs(h[:, 1] - DEPTH).max() < DX, h[:, 1]
    header, v = read_csv(out / "gauges" / "v_mid.csv")
    assert header == ["time [s]", "vx [m/s]", "vy [m/s]"]
    assert np.abs(v[:, 1:]).max() < 0.01 * np.sqrt(G * DEPTH)
    header, rho = read_csv(out / "gauges" / "rho_mid.csv")
    assert header == ["time [s]", "rho [kg/m^3]"] and len(rho) == (len(p) + 1) // 2
    assert np.abs(rho[:, 1] / 1000.0 - 1).max() < 0.01
    # no fluid within h of the point: 0, not NaN
    _, air = read_csv(out / "gauges" / "p_air.csv")
    assert len(air) > 1 and (air[:, 1] == 0).all()


def test_both_backends_write_the_same_csv_bytes(tank_run):
    backend, out, _ = tank_run
    if backend == "numba":
        pytest.skip("compared from the vulkan run")
    numba_out = RUNS.get("numba")
    if numba_out is None:  # (this test alone)
        numba_out = out.parent / "numba_again"
        sphcore.run(tank(), backend="numba", out_dir=numba_out, progress=False)
    for name in ("p_bottom", "v_mid", "rho_mid", "level", "p_air"):
        a, b = (out / "gauges" / f"{name}.csv").read_bytes(), (numba_out / "gauges" / f"{name}.csv").read_bytes()
        assert a == b, name


def test_resume_gives_the_rows_of_a_run_never_stopped(tmp_path):
    scene = tank(checkpoint_every=100)
    whole, parts = tmp_path / "whole", tmp_path / "parts"
    sphcore.run(scene, steps=300, out_dir=whole, progress=False)
    sphcore.run(scene, steps=100, out_dir=parts, progress=False)
    shutil.copy(parts / "checkpoint.npz", tmp_path / "at_100.npz")
    sphcore.resume(parts, steps=200, progress=False)  # rows to step 200, then put back the checkpoint of 100:
    shutil.copy(tmp_path / "at_100.npz", parts / "checkpoint.npz")  # (a run stopped after writing past it)
    assert len(read_csv(parts / "gauges" / "p_bottom.csv")[1]) > len(read_csv(tmp_path / "whole" / "gauges" /
                                                                            "p_bottom.csv")[1]) * 0.6
    sphcore.resume(parts, steps=300, progress=False)
    for name in ("p_bottom", "v_mid", "rho_mid", "level", "p_air"):
        a, b = (whole / "gauges" / f"{name}.csv").read_bytes(), (parts / "gauges" / f"{name}.csv").read_bytes()
        assert a == b, name


def test_plot_draws_the_gauges(tank_run, tmp_path):
    backend, out, _ = tank_run
    if backend != "numba":
        pytest.skip("once")
    from sphcore.plot import plot_gauges

    png = plot_gauges(out)
    assert png == out / "gauges.png" and png.read_bytes().startswith(b"\x89PNG")
    assert plot_gauges(tmp_path) is None  # no gauges, no picture


def body_state(scene, n_body, first, seed):
    """A state of `scene` whose particles carry accelerations of our own, ids permuted, and a force and a moment
    gauge on the body of ids [first, first + n_body)."""
    rng = np.random.default_rng(seed)
    config = dict(scene.config, gauges=[{"name": "F", "quantity": "force", "body": "b", "interval": 0.01},
                                        {"name": "M", "quantity": "moment", "body": "b", "interval": 0.01,
                                         "about": [0.1, 0.2, 0.05][:scene.dim]}])
    scene = Scene(config, scene.source)  # (bodies come with the walls' branch: the table is made by hand here)
    gauges = table(scene, {"b": (first, n_body, [0.0] * scene.dim)})
    x = scene.initial_positions()
    params = scene.params(len(x))
    state = empty_state(params, gauges=gauges)
    state["particle_x"][:, :scene.dim] = x
    state["particle_a"][:, :scene.dim] = rng.normal(0, 10, (len(x), scene.dim))
    state["particle_id"][:] = rng.permutation(len(x))
    state["particle_rho"][:] = 1000.0
    return scene, params, state


@pytest.mark.parametrize("dim", [2, 3])
def test_force_and_moment_on_a_body_reduce_to_the_same_bits(dim, open_backend):
    block = {"min": [0.1] * dim, "max": [0.4] * dim}  # (2D: 225 particles, 3D: 216)
    base = Scene.from_dict({"physics": {"dimension": dim}, "fluid": {"spacing": 0.02 if dim == 2 else 0.05,
                                                                      "blocks": [block]}})
    scene, params, state = body_state(base, n_body=40, first=7, seed=dim)
    stages = plan(scene)
    assert "sample_gauges" in [s.name for s in stages]
    results = []
    for backend in ("numba", "numba", "vulkan"):
        if backend == "vulkan":
            vulkan_or_skip()
        b = open_backend(backend, params, state, stages, scene.spec)
        b.run_stage("sample_gauges")
        results.append((b.read_buffer("gauge_samples"), b.read_buffer("gauge_state")))
    for samples, gauge_state in results[1:]:
        assert np.array_equal(samples.view(np.uint32), results[0][0].view(np.uint32))  # bit for bit
        assert np.array_equal(gauge_state, results[0][1])
    samples, gauge_state = results[0]
    assert gauge_state[1::2, :2].tolist() == [[1, 1], [1, 1]]  # the next multiple, one sample each
    # against float64: F = m sum a, M = sum (x - about) x m a over the body's ids
    mine = (state["particle_id"] >= 7) & (state["particle_id"] < 47)
    a = state["particle_a"][mine, :3].astype(np.float64)
    r = state["particle_x"][mine, :3].astype(np.float64) - np.array([0.1, 0.2, 0.05][:dim] + [0.0] * (3 - dim))
    force, moment = scene.mass * a.sum(0), scene.mass * np.cross(r, a).sum(0)
    np.testing.assert_allclose(samples[0, 1:4], force, rtol=1e-5, atol=1e-6 * np.abs(force).max())
    np.testing.assert_allclose(samples[GAUGE_SLOTS, 1:4], moment, rtol=1e-5, atol=1e-6 * np.abs(moment).max())
    assert samples[0, 0] == 0.0 and samples[GAUGE_SLOTS, 0] == 0.0  # taken at t = 0
    assert columns("force", dim)[0] == ("Fx [N/m]" if dim == 2 else "Fx [N]")


def test_no_sample_is_taken_before_it_is_due_and_the_ring_is_read_before_it_fills(tmp_path):
    """GAUGE_SLOTS + 50 steps with a sample every step: the reads in advance() lose none."""
    scene = Scene.from_dict({"fluid": {"spacing": 0.05}, "time": {"dt": 1e-4},
                             "gauges": [{"name": "p", "quantity": "pressure", "at": [0.2, 0.1], "interval": 1e-4},
                                        {"name": "q", "quantity": "pressure", "at": [0.2, 0.1], "interval": 1e-2}]})
    with sphcore.Simulation(scene) as sim:
        sim.step(GAUGE_SLOTS + 50)
        every, sparse = sim.take_gauge_rows()
    assert len(every) == GAUGE_SLOTS + 50  # one a step, the time of each step's start
    np.testing.assert_allclose(every[:, 0], np.arange(GAUGE_SLOTS + 50) * 1e-4, rtol=1e-5, atol=1e-9)
    np.testing.assert_allclose(sparse[:, 0], [0.0, 0.01, 0.02, 0.03], rtol=1e-5)  # each the first step at or past


@pytest.mark.parametrize("gauge, message", [
    ({"name": "p", "quantity": "pressur", "at": [0.5, 0.5], "interval": 0.01}, "quantity = 'pressur': choose one"),
    ({"name": "p", "quantity": "pressure", "at": [0.5, 1.5], "interval": 0.01}, "at = [0.5, 1.5] is outside"),
    ({"name": "p", "quantity": "pressure", "at": [0.5, 0.5], "interval": 0.0}, "interval = 0.0: must be"),
    ({"name": "p", "quantity": "pressure", "at": [0.5, 0.5], "interval": -1}, "interval = -1: must be"),
    ({"name": "p", "quantity": "force", "interval": 0.01}, "a force gauge needs body"),
    ({"name": "p", "quantity": "moment", "body": "tank", "interval": 0.01}, "body = 'tank': no such body"),
    ({"name": "p", "quantity": "pressure", "interval": 0.01}, "a pressure gauge needs at"),
    ({"name": "p", "quantity": "pressure", "at": [0.5, 0.5], "interval": 0.01, "where": 1}, "unknown key 'where'"),
    ({"name": "a/b", "quantity": "pressure", "at": [0.5, 0.5], "interval": 0.01}, "must be a file name"),
    ({"name": "p", "quantity": "pressure", "at": [0.5, 0.5, 0.5], "interval": 0.01}, "has 3 components"),
])
def test_bad_gauges_are_refused_in_one_line(gauge, message):
    with pytest.raises(SceneError, match="gauges") as e:
        Scene.from_dict({"gauges": [gauge]})
    assert message in str(e.value) and "\n" not in str(e.value)


def test_two_gauges_of_one_name_are_refused():
    gauge = {"name": "p", "quantity": "pressure", "at": [0.5, 0.5], "interval": 0.01}
    with pytest.raises(SceneError, match=r"gauges\[1\] \(p\): a second gauge named 'p'"):
        Scene.from_dict({"gauges": [gauge, gauge]})


def test_a_scene_without_gauges_has_no_gauge_stage():
    assert "sample_gauges" not in [s.name for s in plan(Scene.from_dict({}))]


def small():
    return Scene.from_dict({"name": "small", "fluid": {"spacing": 0.05}, "time": {"steps": 5, "output_every": 5},
                            "gauges": [{"name": "p", "quantity": "pressure", "at": [0.2, 0.1], "interval": 1e-4}]})


def test_gauge_files_belong_to_the_run_folder(tmp_path):
    """Written through the run's folder: listed in its manifest, deleted by --overwrite, and a file of the user's
    under a gauge's name is never replaced."""
    from sphcore.errors import FolderError

    out = tmp_path / "run"
    sphcore.run(small(), out_dir=out, progress=False)
    assert "gauges/p.csv" in (out / "sphcore-run.json").read_text()
    assert len(read_csv(out / "gauges" / "p.csv")[1]) == 5
    (out / "gauges" / "mine.csv").write_text("kept")
    sphcore.run(small(), out_dir=out, progress=False, overwrite=True)
    assert len(read_csv(out / "gauges" / "p.csv")[1]) == 5 and (out / "gauges" / "mine.csv").read_text() == "kept"
    theirs = tmp_path / "theirs"
    (theirs / "gauges").mkdir(parents=True)
    (theirs / "gauges" / "p.csv").write_text("the user's")
    with pytest.raises(FolderError, match="gauges/p.csv: a file no sphcore run wrote"):
        sphcore.run(small(), out_dir=theirs, progress=False)
    assert (theirs / "gauges" / "p.csv").read_text() == "the user's"
