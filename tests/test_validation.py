"""The dam break against Martin & Moyce (1952): measurement definitions, the front's error at a
coarse resolution, the residual column's physics, and `sphcore validate dam-break`."""
import csv
import json
import math
import os

import numpy as np
import pytest

from sphcore.validate import dam_break
from sphcore.validate.dam_break import G, SETTINGS, dam_break_scene, measure, min_neighbours, read_series, rms_z


def test_measurements_at_rest_are_the_column():
    scene = dam_break_scene({"resolution": 10})
    x = scene.initial_positions().astype(np.float64)
    front, height = measure(scene, x)
    assert front == pytest.approx(SETTINGS["a"], abs=1e-6)
    assert height == pytest.approx(2 * SETTINGS["a"], abs=1e-6)


def test_spray_is_not_the_front_but_a_thin_film_is():
    scene = dam_break_scene({"resolution": 10})
    dx, a = scene["fluid.spacing"], SETTINGS["a"]
    x = scene.initial_positions().astype(np.float64)
    assert min_neighbours(scene) == 3  # 8 neighbours inside a 2D lattice at h = 2 dx
    droplets = np.array([[3 * a, dx / 2], [3 * a + dx, dx / 2]])  # a pair far ahead
    film = np.array([[a + dx / 2 + i * dx, dx / 2 + j * dx] for i in range(10) for j in range(2)])
    front, _ = measure(scene, np.vstack([x, droplets]))
    assert front == pytest.approx(a, abs=1e-6)
    front, _ = measure(scene, np.vstack([x, film, droplets]))
    assert front == pytest.approx(a + 10 * dx, abs=1e-6)


def test_experimental_series_are_carried_with_their_headers():
    for name in dam_break.FRONT_SERIES:
        T, Z, header = read_series(name)
        assert "Martin" in header or "Koshizuka" in header
        assert len(T) >= 8 and np.all(np.diff(T) > 0) and np.all(np.diff(Z) > 0)


@pytest.fixture(scope="module")
def coarse_run():
    return dam_break.run_dam_break({"resolution": 20, "t_end": 0.42}, progress=False)


def test_front_follows_martin_and_moyce_at_a_coarse_resolution(coarse_run):
    rows, summary = coarse_run
    assert summary["points_table2"] == 15  # every tabulated point up to T = 3.33 is compared
    assert summary["rms_Z_table2"] < 0.15
    # the gate-release shift is the literature's (Lethe: 0.175), and the data agree with it
    assert 0.05 <= summary["best_shift_T_table2"] <= 0.35
    Z = np.array([r["Z"] for r in rows])
    assert np.all(np.diff(Z) > -0.05)  # the surge does not retreat


def test_residual_column_follows_the_physics(coarse_run):
    rows, _ = coarse_run
    tau = np.array([r["tau"] for r in rows])
    H = np.array([r["H"] for r in rows])
    assert np.isfinite(H).all()
    assert np.all(H >= 1 - tau**2 / 4 - 0.02)  # the top cannot fall faster than free fall
    assert np.all(np.diff(H) < 0.03)  # the column only drains (up to the particle scale)
    assert H[tau <= 0.3].min() > 0.97  # the top barely moves at first
    assert H[-1] < 0.6  # and has fallen by more than 40 % at tau = 2.6
    # mass conservation in shallow-water terms: what left the column is in the surge
    T = np.array([r["T"] for r in rows])
    assert np.interp(2.0, T, [r["Z"] for r in rows]) > 2.0


def test_rms_is_zero_against_itself_and_sees_a_shift():
    T, Z, _ = read_series("table2")
    rows = [{"T": t, "Z": z} for t, z in zip(np.r_[0.0, T, 4.0], np.r_[1.0, Z, 4.5])]
    assert rms_z(rows, "table2")[0] == pytest.approx(0.0, abs=1e-12)
    assert rms_z(rows, "table2", 0.2)[0] > 0.1


def test_validate_dam_break_cli(tmp_path):
    from sphcore.cli import main

    out = tmp_path / "v"
    assert main(["validate", "dam-break", "--resolution", "8", "--t-end", "0.05", "--out", str(out)]) == 0
    with open(out / "dam_break_2d.csv") as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0]) == ["t", "front_x", "column_height", "T", "Z", "tau", "H"]
    a = SETTINGS["a"]
    for r in rows:
        t = float(r["t"])
        assert float(r["T"]) == pytest.approx(t * math.sqrt(2 * G / a), rel=1e-4, abs=1e-6)
        assert float(r["tau"]) == pytest.approx(t * math.sqrt(G / a), rel=1e-4, abs=1e-6)
        assert float(r["Z"]) == pytest.approx(float(r["front_x"]) / a, rel=1e-4)
        assert float(r["H"]) == pytest.approx(float(r["column_height"]) / (2 * a), rel=1e-4)
    dt = dam_break_scene({"resolution": 8}).dt
    assert 0.05 <= float(rows[-1]["t"]) < 0.05 + dt
    assert (out / "dam_break_2d.png").stat().st_size > 10_000
    assert (out / "dam_break_2d.json").is_file()


def test_neighbour_counts_match_all_pairs():
    """The front's neighbour test looks only in each batch's box grown by h: the same counts as all pairs."""
    from sphcore.validate.dam_break import neighbour_counts
    rng = np.random.default_rng(3)
    x = rng.random((3000, 3)) * [1.0, 0.5, 0.2]
    h, candidates = 0.05, np.argsort(x[:, 0])[::-1][:300]
    d2 = ((x[candidates][:, None, :] - x[None, :, :]) ** 2).sum(axis=2)
    expected = (d2 < h * h * (1 - 1e-5)).sum(axis=1) - 1
    assert expected.max() > 5
    assert np.array_equal(neighbour_counts(x, candidates, h), expected)


@pytest.mark.parametrize("case, argv, stem", [
    ("dam-break", ["--resolution", "8"], "dam_break_2d"),
    ("dam-break-pressure", ["--resolution", "8", "--t-end-star", "3"], "dam_break_pressure"),
    ("tank", ["--resolution", "8", "--t-end", "0.3"], "tank"),
    ("spheric", ["--spacing", "0.08", "--t-end", "0.3"], "spheric_test2"),
])
def test_a_validation_run_stopped_by_a_signal_keeps_its_samples(tmp_path, capsys, monkeypatch, case, argv, stem):
    """SIGTERM during the steps (here sent from the third call of Simulation.advance): the run stops at
    the next sample, writes the samples it has with the summary naming the signal, and exits 128 + 15; a
    second signal during the steps would stop them at once."""
    import signal

    from sphcore.cli import main
    from sphcore.simulation import Simulation

    calls = []
    advance = Simulation.advance

    def advance_and_signal(self, steps):
        calls.append(steps)
        if len(calls) == 3:
            os.kill(os.getpid(), signal.SIGTERM)
        advance(self, steps)

    monkeypatch.setattr(Simulation, "advance", advance_and_signal)
    out = tmp_path / "out"
    assert main(["validate", case, "--out", str(out), *argv]) == 128 + signal.SIGTERM
    err = capsys.readouterr().err
    assert "interrupted by SIGTERM at t = " in err and f"are in {out}" in err, err
    assert len(calls) == 3  # no step after the signal
    with open(out / f"{stem}.csv") as f:
        assert len(list(csv.DictReader(f))) == 4  # the samples before each of the three calls, and after
    summary = json.loads((out / f"{stem}.json").read_text())
    assert summary["signal"] == signal.SIGTERM and "SIGTERM" in summary["error"]
