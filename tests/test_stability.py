"""The stability matrix: every extreme ends stable (asserted: finite, energy bounded, inside the
box) or detected (stopped at the first bad step, naming step, particle and cause, with the
snapshots before it kept)."""
import math

import numpy as np
import pytest

from sphcore.scene import stable_dt
from sphcore.simulation import Simulation, run
from sphcore.validate import stability


@pytest.fixture(scope="module")
def matrix(tmp_path_factory):
    out = tmp_path_factory.mktemp("stability")
    return out, {row["case"]: row for row in stability.run_matrix(out, progress=False)}


def test_every_case_ends_stable_or_detected(matrix):
    out, rows = matrix
    assert set(rows) == set(stability.cases())
    for name, row in rows.items():
        assert row["status"] in ("stable", "detected"), row
        assert row["status"] == row["expected"], row
        if row["status"] == "stable":
            assert row["speed_max"] <= row["speed_limit"] and math.isfinite(row["energy_max"])
        else:
            assert row["step"] > 0 and row["particle"] != "" and row["cause"], row
            assert row["snapshots"] >= 1  # what was written before the blow-up is kept
    assert (out / "stability.json").is_file() and (out / "stability.csv").is_file()


def test_past_the_bound_names_the_time_step(matrix):
    _, rows = matrix
    row = rows["dt_10x_bound"]
    assert row["dt"] == pytest.approx(10 * row["dt_bound"], rel=1e-9)
    assert "exceeds the CFL bound" in row["cause"]


def test_the_causes_are_named(matrix):
    _, rows = matrix
    assert "no viscosity" in rows["viscosity_0"]["cause"]
    assert "from a wall" in rows["walls_and_corners"]["cause"]


def test_detection_stops_at_the_first_bad_step(matrix, tmp_path):
    """One step fewer than the step named runs clean, through the same checks."""
    _, rows = matrix
    row = rows["dt_10x_bound"]
    scene, _, _ = stability.cases()["dt_10x_bound"]
    run(scene, "numba", steps=row["step"] - 1, out_dir=tmp_path, progress=False)


def test_one_particle_falls_freely_and_stays_inside(tmp_path):
    scene, _, _ = stability.cases()["one_particle"]
    sim = Simulation(scene)
    y0 = float(sim.read()["particle_x"][0, 1])
    steps = int(0.1 / scene.dt)
    sim.advance(steps)
    y = float(sim.read()["particle_x"][0, 1])
    t = steps * scene.dt
    assert y == pytest.approx(y0 - 9.81 * t * t / 2, abs=9.81 * t * scene.dt)  # symplectic Euler: O(dt) in x
    sim.close()


def test_two_coincident_particles_stay_finite_and_fall_together():
    """r = 0 between them must not give NaN (normalize(0)); two particles alone are far below the
    rest density, so their pressure is clamped to 0 and nothing pushes them apart."""
    scene, positions, _ = stability.cases()["two_coincident"]
    sim = Simulation(scene)
    stability.place(sim, positions(scene))
    x0 = sim.read()["particle_x"]
    assert np.array_equal(x0[0], x0[1])
    sim.advance(20)
    state = sim.read()
    sim.close()
    x = state["particle_x"]
    assert np.isfinite(x).all() and np.isfinite(state["particle_v"]).all()
    assert state["particle_p"].max() == 0 and state["particle_rho"].max() < scene["fluid.rest_density"]
    assert np.array_equal(x[0], x[1]) and x[0, 1] < x0[0, 1]


def test_auto_dt_is_the_bound_times_the_fraction():
    scene, _, _ = stability.cases()["viscosity_1e4"]
    dt_max, bound = stable_dt(scene, scene.speed_estimate())
    assert bound == "viscous" and scene.dt == pytest.approx(dt_max)
