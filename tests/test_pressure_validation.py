"""Issue 12's pressure validation: the wall sensor on a hydrostatic column (rho g depth), the
impact peak and RMS metrics on constructed series, the hydrostatic tank's figures, the named
configurations, the command's options, and a tiny run of Buchner's dam break on numba."""
import csv
import json
import math

import numpy as np
import pytest

from sphcore.cli import main
from sphcore.scene import SceneError
from sphcore.validate import buchner, configs, tank
from sphcore.validate.sensors import wall_pressure

RHO_G = 1000.0 * 9.81


def column(width, depth, dx):
    """Particles at the cell centres of a lattice filling [0, width] x [0, depth], with p = rho g (depth - y)."""
    xs = np.arange(round(width / dx)) * dx + dx / 2
    ys = np.arange(round(depth / dx)) * dx + dx / 2
    x = np.stack(np.meshgrid(xs, ys, indexing="ij"), -1).reshape(-1, 2)
    return x, RHO_G * (depth - x[:, 1])


@pytest.mark.parametrize("wall_x", [0.0, 1.0])
def test_wall_sensor_reads_rho_g_depth_on_a_hydrostatic_column(wall_x):
    dx, depth, h = 0.02, 0.6, 0.04
    x, p = column(1.0, depth, dx)
    lo, hi = (0.0, 0.0), (1.0, 2.0)
    for y in (0.1, 0.16, 0.25, 0.4, 0.5):  # at least h from the floor and the surface
        read = wall_pressure(x, p, (wall_x, y), h, lo, hi)
        assert read == pytest.approx(RHO_G * (depth - y), rel=2e-3, abs=1.0), y
    # the images make the support whole: without them the reading is the same on a vertical wall
    # (they only double numerator and denominator) ...
    assert wall_pressure(x, p, (wall_x, 0.16), h, lo, (5.0, 5.0) if wall_x == 0 else hi) == pytest.approx(
        wall_pressure(x, p, (wall_x, 0.16), h, lo, hi), rel=1e-9)
    # ... and in the corner the floor's images read low by at most rho g h / 2
    corner = wall_pressure(x, p, (wall_x, 0.0), h, lo, hi)
    assert RHO_G * (depth - h / 2) <= corner < RHO_G * depth
    # dry: no particle within h
    assert wall_pressure(x, p, (wall_x, depth + h + dx), h, lo, hi) == 0.0


def test_wall_sensor_at_the_buchner_sensor_of_a_resting_column():
    """The case's own sensor (P1 at y = 0.16 on the far wall) under a layer at rest, at the
    case's resolutions: rho g (D - 0.16) within 0.5 %."""
    for resolution in (10, 30, 60):
        dx = buchner.SETTINGS["H"] / resolution
        scene_w = buchner.TANK_LENGTH * buchner.SETTINGS["H"]
        x, p = column(scene_w, 0.6, dx)
        read = wall_pressure(x, p, (scene_w, buchner.SENSOR_Y), 2 * dx, (0, 0), (scene_w, buchner.TANK_HEIGHT))
        assert read == pytest.approx(RHO_G * (0.6 - buchner.SENSOR_Y), rel=5e-3), resolution


def test_impact_peak_and_rms_on_constructed_series():
    t = np.linspace(0.0, 8.0, 801)
    p = np.where(t > 2.5, 0.5, 0.0) + np.exp(-((t - 2.8) / 0.05) ** 2)  # a spike on a step
    assert buchner.impact_peak(t, p) == pytest.approx((2.8, 1.5), abs=1e-9)
    assert buchner.impact_peak(t, p, window=(3.5, 4.0))[1] == pytest.approx(0.5)
    assert all(math.isnan(v) for v in buchner.impact_peak(t, p, window=(9.0, 10.0)))
    # RMS: zero against itself; a constant offset; only the measured times within [0, until] and the run
    rms, n = buchner.rms_against(t, p, t, p)
    assert rms == 0.0 and n == 701  # t <= 7
    rms, n = buchner.rms_against(t, p + 0.1, t[::10], p[::10], until=7.0)
    assert rms == pytest.approx(0.1) and n == 71
    rms, n = buchner.rms_against(t[:301], p[:301], t, p)  # the run ends at t = 3: later data are not counted
    assert rms == 0.0 and n == 301
    # linear interpolation of the simulation at the measured times
    assert buchner.rms_against([0.0, 2.0], [0.0, 2.0], [1.0], [1.5])[0] == pytest.approx(0.5)


def test_the_measured_series_meets_every_target_against_itself():
    t_exp, p_exp, header = buchner.read_measured()
    assert "Buchner" in header and "y=0.160" in header
    assert np.all(np.diff(t_exp) > 0) and 2.0 < t_exp[0] < 2.1 and t_exp[-1] > 7.0
    e = buchner.errors(t_exp, p_exp)
    assert (e["peak_t_star_measured"], e["peak_p_star_measured"]) == pytest.approx((2.77411, 0.68698))
    assert e["peak_time_error"] == 0.0 and e["peak_height_error"] == 0.0 and e["rms_p_star"] == 0.0
    assert e["meets"] == {"peak_time": True, "peak_height": True, "rms": True}
    late = buchner.errors(t_exp + 0.2, p_exp * 1.3)  # 7 % late, 30 % high
    assert late["meets"] == {"peak_time": False, "peak_height": False, "rms": False}
    assert late["peak_time_error"] == pytest.approx(0.2 / 2.77411) and late["peak_height_error"] == pytest.approx(0.3)


def test_tank_profile_of_an_exact_hydrostatic_field():
    dx, depth = 0.02, 0.6
    x, p = column(1.0, depth, dx)
    f = tank.profile(x, p, 2 * dx, depth)
    assert f["slope_error"] == pytest.approx(0.0, abs=1e-9) and f["deviation_max"] == pytest.approx(0.0, abs=1e-9)
    f = tank.profile(x, 1.02 * p + 300.0, 2 * dx, depth)  # 2 % steep, offset by 300 Pa
    assert f["slope_error"] == pytest.approx(0.02)
    assert f["deviation_max"] == pytest.approx((0.02 * RHO_G * (depth - 4 * dx) + 300.0) / (RHO_G * depth), rel=0.05)


def test_configurations_name_scene_keys():
    assert configs.overrides({}) == {}
    eng = configs.overrides({"config": "engineering", "alpha": 0.05})  # its alpha goes with its smoothing ratio
    assert eng["physics.kernel"] == "wendland_c2" and eng[configs.ALPHA_KEY] == 0.01
    assert configs.overrides({"config": "artificial", "alpha": 0.05})[configs.ALPHA_KEY] == 0.05
    assert configs.overrides({"config": "graphics", "kernel": "wendland_c2"}) == {"physics.kernel": "wendland_c2"}
    assert configs.overrides({"adaptive_dt": True}) == {"time.dt": "adaptive"}
    assert configs.overrides({"config": "dfsph", "cfl_number": 0.8}) == {"physics.pressure_solver": "dfsph",
                                                                          "time.cfl_number": 0.8}
    with pytest.raises(SceneError, match="--config nope: no such configuration"):
        configs.overrides({"config": "nope"})
    with pytest.raises(SceneError, match="physics.no_such_switch"):
        configs.require({"physics.no_such_switch": 1})
    assert configs.apply({"physics": {"dimension": 2}}, {"physics.equation_of_state": "tait"}) == {
        "physics": {"dimension": 2, "equation_of_state": "tait"}}


def test_a_cfl_number_out_of_range_is_refused_naming_the_key(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["validate", "dam-break", "--out", str(out), "--pressure-solver", "dfsph", "--cfl-number", "1.5"]) == 1
    assert "time.cfl_number = 1.5: must be within [0.01, 1]" in capsys.readouterr().err and not out.exists()


@pytest.mark.parametrize("argv, message", [
    (["--resolution", "0"], "--resolution"),
    (["--resolution", "2.5"], "--resolution"),
    (["--t-end-star", "-1"], "--t-end-star"),
    (["--config", "nope"], "--config"),
    (["--kernel", "cubic"], "--kernel"),
    (["--density-diffusion", "antuono"], "--density-diffusion"),
    (["--delta", "0"], "--delta"),
    (["--cfl-number", "0"], "--cfl-number"),
    (["--backend", "cuda"], "--backend"),
])
def test_bad_options_are_rejected_naming_them(tmp_path, capsys, argv, message):
    with pytest.raises(SystemExit) as e:
        main(["validate", "dam-break-pressure", "--out", str(tmp_path), *argv])
    assert e.value.code == 2 and message in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["validate", "tank", "--out", str(tmp_path), *argv])
    assert not any(tmp_path.iterdir())


def test_a_resolution_too_coarse_is_one_line(tmp_path, capsys):
    assert main(["validate", "dam-break-pressure", "--out", str(tmp_path), "--resolution", "3"]) == 1
    err = capsys.readouterr().err
    assert "resolution = 3" in err and err.count("\n") == 1


def test_tiny_buchner_run_on_numba(tmp_path):
    out = tmp_path / "p"
    assert main(["validate", "dam-break-pressure", "--out", str(out), "--resolution", "8", "--t-end-star", "3.2"]) in (0, None)
    with open(out / "dam_break_pressure.csv") as f:
        rows = [{k: float(v) for k, v in r.items()} for r in csv.DictReader(f)]
    assert list(rows[0]) == ["t", "t_star", "p_star", "p_star_6mm", "p_star_30mm", "p_star_60mm"]
    for r in rows:
        assert r["t_star"] == pytest.approx(r["t"] * math.sqrt(9.81 / 0.6), rel=1e-4, abs=1e-6)
    t = np.array([r["t_star"] for r in rows])
    assert np.all(np.diff(t) > 0) and t[-1] >= 3.2 - 1e-6 and np.diff(t).max() < 2 * buchner.SAMPLE_DT_STAR
    p = np.array([r["p_star"] for r in rows])
    assert np.all(p[t < 1.5] == 0.0)  # dry until the surge arrives (t* about 2.5)
    assert p[t > 2.6].max() > 0.2  # and then loaded
    summary = json.loads((out / "dam_break_pressure.json").read_text())
    assert summary["particles"] == 16 * 8 and summary["error"] is None and summary["settings"]["config"] == "graphics"
    assert summary["rms_points"] > 10 and math.isfinite(summary["rms_p_star"])
    assert set(summary["meets"]) == {"peak_time", "peak_height", "rms"}
    assert (out / "dam_break_pressure.png").stat().st_size > 10_000
    # the peers' series (validation/data) beside ours, measured the same way
    assert sorted(summary["peers"]) == sorted(f"{peer} {res}" for peer, (_, columns) in buchner.PEERS.items()
                                              for res in columns)
    for label, peer in summary["peers"].items():
        assert peer["rms_points"] > 50 and 0.0 < peer["rms_p_star"] < 1.0, label
    # De Courcy et al.'s simulation at every sensor: the RMS is rms_against's of our column at their times
    reference = buchner.read_reference()
    assert set(summary["reference"]) == set(buchner.REFERENCE) == set(rows[0]) - {"t", "t_star"}
    for column, metrics in summary["reference"].items():
        rms, count = buchner.rms_against(t, [r[column] for r in rows], *reference[column])
        assert count == metrics["rms_points"] > 50 and metrics["rms_p_star"] == pytest.approx(rms, rel=1e-2), column  # (the CSV keeps 6 digits)
    assert summary["rms_p_star_reference"] == summary["reference"]["p_star"]["rms_p_star"]
    for column in buchner.REFERENCE:  # every sensor dry until the surge arrives, and then loaded
        assert all(r[column] == 0.0 for r in rows if r["t_star"] < 1.5) and max(r[column] for r in rows) > 0.2, column


def test_peer_metrics_are_ours_applied_to_their_series():
    """Each peer's RMS is errors()' RMS of its own columns: a peer series replaced by the measured one
    scores zero, and one shifted by 0.1 scores 0.1."""
    t_exp, p_exp, _ = buchner.read_measured()
    assert buchner.errors(t_exp, p_exp)["rms_p_star"] == pytest.approx(0.0, abs=1e-12)
    assert buchner.errors(t_exp, p_exp + 0.1)["rms_p_star"] == pytest.approx(0.1, rel=1e-9)
    series = buchner.read_peers()
    for label, metrics in buchner.peer_errors().items():
        t, p = series[label]
        assert np.all(np.diff(t) >= 0) and t[0] < 2.47 and t[-1] > 6.5, label  # the impact and the plateau covered
        assert metrics["rms_p_star"] == pytest.approx(buchner.errors(t, p)["rms_p_star"], rel=1e-12)
    for label, (t, p) in buchner.read_reference().items():  # De Courcy et al.'s series: the impact and the plateau
        assert np.all(np.diff(t) >= 0) and t[0] < 2.47 and t[-1] > 6.5, label


def test_reference_metrics_pair_each_sensor_with_its_series(monkeypatch):
    """reference_errors takes each sample column against its own reference series, at the series' times:
    samples equal to it score zero, samples 0.1 above it score 0.1, and a column paired with another
    sensor's series would not."""
    t = np.linspace(2.4, 7.0, 200)
    series = {column: (t, np.exp(-(t - 3.0 - 0.2 * k) ** 2 / 0.1)) for k, column in enumerate(buchner.REFERENCE)}
    monkeypatch.setattr(buchner, "read_reference", lambda: series)
    times = np.linspace(0.0, 7.3, 731)
    for shift in (0.0, 0.1):
        rows = [{"t_star": ts, **{c: math.exp(-(ts - 3.0 - 0.2 * k) ** 2 / 0.1) + shift for k, c in enumerate(series)}}
                for ts in times]
        for column, metrics in buchner.reference_errors(rows).items():
            assert metrics["rms_points"] == 200 and metrics["rms_p_star"] == pytest.approx(shift, abs=2e-4), column
            assert metrics["peak_t_star"] == pytest.approx(metrics["reference_peak_t_star"], abs=0.01)


def test_report_shows_each_configurations_figures(tmp_path):
    from sphcore.validate import report

    results = tmp_path / "results"
    for config, rms, res in (("graphics", 1.2345, 30), ("engineering", 0.0876, 60)):
        folder = results / "model" / f"buchner_{config}_{res}"
        folder.mkdir(parents=True)
        summary = {"settings": {**buchner.SETTINGS, "config": config, "resolution": res}, "particles": 2 * res * res,
                   "peak_p_star": 0.7, "peak_time_error": 0.01, "peak_height_error": -0.05, "rms_p_star": rms,
                   "wall_s": 12.5, "error": None}
        (folder / "dam_break_pressure.json").write_text(json.dumps(summary))
    (results / "tank.json").write_text(json.dumps({"settings": {**tank.SETTINGS, "config": "engineering"},
                                                   "slope_error": 0.0123, "deviation_max": 0.0456}))
    (results / "dam_break_2d.json").write_text(json.dumps({"settings": {"resolution": 20}, "rms_Z_table2": 0.0501}))
    page = report.build_report(tmp_path / "out", results=results).read_text()
    model = page[page.index('id="model"'):page.index('id="dam_break_3d"')]
    for text in ("Buchner 2002, P1 pressure", "1.234", "0.0876", "Hydrostatic tank", "1.23", "4.56", "0.0501",
                 "wendland_c2"):
        assert text in model, text
    assert model.index("1.234") < model.index("0.0876")  # today's model first, then the recommended
