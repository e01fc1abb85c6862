"""Per-stage profiles (sphcore.profile): every stage of the plan timed, as often as the plan runs it,
on both backends; the pair-test count of the roofline note against a brute-force count."""
from collections import Counter

import numpy as np
import pytest

from conftest import BACKENDS, vulkan_or_skip
from sphcore.backends import plan
from sphcore.profile import Profile, pair_tests
from sphcore.scene import Scene
from sphcore.simulation import Simulation


def small_scene(**physics):
    return Scene.from_dict({"physics": {"model": "graphics", **physics}, "domain": {"box_max": [0.3, 0.3]},
                            "fluid": {"blocks": [{"min": [0.0, 0.0], "max": [0.1, 0.1]}]}})


@pytest.mark.parametrize("backend", BACKENDS)
def test_profile_times_every_stage_as_often_as_the_plan_runs_it(backend):
    if backend == "vulkan":
        vulkan_or_skip()
    scene, profile = small_scene(), Profile()
    with Simulation(scene, backend, profile=profile) as sim:
        sim.step(7)
    expected = Counter(stage.name for stage in plan(scene))
    assert profile.steps == 7 and profile.calls == {name: 7 * k for name, k in expected.items()}
    assert all(seconds > 0 for seconds in profile.seconds.values())
    rows = profile.rows()
    assert sum(r["share"] for r in rows) == pytest.approx(1.0)
    assert [r["ms_per_step"] for r in rows] == sorted((r["ms_per_step"] for r in rows), reverse=True)


@pytest.mark.parametrize("boundary", ["walls", "open"])
@pytest.mark.parametrize("split", [1, 2])
def test_pair_tests_count_every_candidate_in_the_cells_around(boundary, split):
    scene = Scene.from_dict({"physics": {"model": "graphics"}, "domain": {"boundary": boundary, "box_max": [0.3, 0.2]},
                             "fluid": {"blocks": [{"min": [0.0, 0.0], "max": [0.3, 0.2]}],
                                       "smoothing_ratio": 2.0 * split}})
    assert scene.cell_split == split
    rng = np.random.default_rng(3)
    x = rng.uniform(0.0, 1.0, (300, 2)) * [0.3, 0.2]
    if boundary == "open":
        x[:50] += [0.9, -0.6]  # outside the period: hashed back into it
    dims = np.array(scene.grid_dim[:2])
    cell = np.floor((x - scene["domain.box_min"]) / (scene.h * (1 + 2.0**-12) / split)).astype(int)
    if boundary == "open":
        cell %= dims
    d = np.abs(cell[:, None, :] - cell[None, :, :])
    if boundary == "open":
        d = np.minimum(d, dims - d)  # neighbouring across the period
    assert pair_tests(scene, x) == int((d <= split).all(axis=2).sum())


def test_run_profile_prints_and_saves_the_table(tmp_path, capsys):
    import json

    from sphcore.cli import main
    assert main(["run", "tank_2d", "--steps", "3", "--out", str(tmp_path / "run"), "--profile"]) == 0
    out = capsys.readouterr().out
    assert "per-stage profile on cpu (numba), 3 steps" in out and "compute_forces" in out
    saved = json.loads((tmp_path / "run" / "profile.json").read_text())
    assert saved["steps"] == 3 and {r["stage"] for r in saved["stages"]} == {s.name for s in plan(Scene.load("tank_2d"))}
