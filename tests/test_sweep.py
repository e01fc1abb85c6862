"""The speed/accuracy sweep (`sphcore sweep`): every point gathered through Dask, a failing point
recorded without stopping the others, points already done not run again; the Pareto front and
the recommendations on synthetic tables; the design; the command's errors."""
import csv
import json
import math

import numpy as np
import pytest

from sphcore.cli import main
from sphcore.validate import sweep
from sphcore.validate.sweep import AXES, DEFAULT, at, pareto_front, recommendations

TINY = {"resolution": 8, "t_end": 0.05}  # 128 particles, about 110 steps


def test_sweep_gathers_every_point_and_records_a_failure(tmp_path):
    points = [at(**TINY), at(**{**TINY, "resolution": 10}), at(**TINY, equation_of_state="ideal_gas"),
              at(**TINY, dt_fraction=0.5)]
    rows = sweep.run_sweep(tmp_path, points=points, workers=1, progress=False)

    assert [r["point"] for r in rows] == [0, 1, 2, 3]
    assert [r["status"] for r in rows] == ["ok", "ok", "failed", "ok"]
    failed = rows[2]
    assert failed["error"].startswith("SceneError: ") and "physics.equation_of_state" in failed["error"]
    for r, res in zip([rows[0], rows[1], rows[3]], [8, 10, 8]):
        assert r["particles"] == 2 * res * res  # a column res wide and 2 res high
        assert r["steps"] > 0 and r["wall_s"] > 0 and r["steps_per_s"] == pytest.approx(r["steps"] / r["wall_s"])
        assert math.isfinite(r["rms_Z_table2"]) and r["points_table2"] > 0
        assert r["dtype"] == "float32" and r["device"].startswith("cpu")
    assert rows[3]["dt"] == pytest.approx(rows[0]["dt"] / 2, rel=1e-6)  # half the stability bound

    with open(tmp_path / "sweep.csv", newline="") as f:
        table = list(csv.DictReader(f))
    assert [t["status"] for t in table] == ["ok", "ok", "failed", "ok"]
    assert [int(t["particles"] or 0) for t in table] == [128, 200, 0, 128]
    stored = json.loads((tmp_path / "sweep.json").read_text())
    assert [r.get("wall_s") for r in stored["rows"]] == [r.get("wall_s") for r in rows]
    assert stored["sweep"]["points"] == 4 and stored["sweep"]["workers"] == 1
    rec = json.loads((tmp_path / "recommendations.json").read_text())
    assert [f["point"] for f in rec["failed"]] == [2]
    assert (tmp_path / "pareto.png").stat().st_size > 10_000

    # again with the points that ran: nothing runs (no cluster), the rows are the same, the failed
    # point (not in this design) is kept after them
    again = sweep.run_sweep(tmp_path, points=[points[0], points[1], points[3]], progress=False)
    assert [r["wall_s"] for r in again[:3]] == [rows[0]["wall_s"], rows[1]["wall_s"], rows[3]["wall_s"]]
    assert again[3]["status"] == "failed" and again[3]["equation_of_state"] == "ideal_gas"


def synthetic(*specs):
    """Rows from (cost, error, changes to the default point[, status])."""
    rows = []
    for i, (cost, error, changes, *status) in enumerate(specs):
        p = at(**changes)
        rows.append({**p, "point": i, "varied": sweep.varied(p), "status": status[0] if status else "ok",
                     "wall_s": cost, "rms_Z_table2": error, "error": "SimulationError: blow-up" if status else ""})
    return rows


def test_pareto_front_keeps_only_the_non_dominated_points():
    rows = synthetic((1.0, 0.5, {}), (2.0, 0.3, {"resolution": 16}), (3.0, 0.4, {"resolution": 25}),
                     (4.0, 0.1, {"resolution": 56}), (2.0, 0.3, {"dt_fraction": 0.5}),
                     (5.0, 0.1, {"dt_fraction": 0.25}), (0.5, math.nan, {"alpha": 0.1}),
                     (0.1, 0.01, {"dt_fraction": 2.0}, "failed"), (1.0, 0.6, {"stiffness": 225.0}))
    assert [r["point"] for r in pareto_front(rows)] == [0, 1, 4, 3]  # 2, 5, 8 dominated; 6 NaN; 7 failed

    rng = np.random.default_rng(5)
    rows = synthetic(*[(float(c), float(e), {"resolution": i}) for i, (c, e) in
                       enumerate(zip(rng.integers(1, 8, 60), rng.integers(1, 8, 60)))])
    front = {r["point"] for r in pareto_front(rows)}
    beats = lambda q, p: q["wall_s"] <= p["wall_s"] and q["rms_Z_table2"] <= p["rms_Z_table2"] and (  # noqa: E731
        q["wall_s"] < p["wall_s"] or q["rms_Z_table2"] < p["rms_Z_table2"])
    for p in rows:
        assert (p["point"] in front) == (not any(beats(q, p) for q in rows))


def test_recommendations_pick_the_right_rows():
    rows = synthetic((40.0, 0.12, {}), (1.0, 0.30, {"resolution": 10}), (2.5, 0.15, {"resolution": 16}),
                     (9.0, 0.14, {"resolution": 25}), (100.0, 0.05, {"resolution": 56}),
                     (80.0, 0.11, {"dt_fraction": 0.5}), (18.0, math.nan, {"dt_fraction": 2.0}, "failed"),
                     (0.5, 0.20, {"resolution": 10, "equation_of_state": "tait"}),
                     (3.0, 0.16, {"resolution": 16, "equation_of_state": "tait"}))
    rec = recommendations(rows)
    assert rec["cheapest_meeting_threshold"]["point"] == 2  # 0.15 meets RMS <= 0.15
    assert rec["most_accurate"]["point"] == 4
    assert [f["point"] for f in rec["failed"]] == [6]
    assert recommendations(rows, threshold=0.01)["cheapest_meeting_threshold"] is None

    around = {tuple(g["context"].items()): g for g in rec["effects"]["dt_fraction"]}[()]
    assert [(v["dt_fraction"], v["status"]) for v in around["values"]] == [(0.5, "ok"), (1.0, "ok"), (2.0, "failed")]
    assert around["rms_spread"] == pytest.approx(0.01)
    ladders = {tuple(g["context"].items()): g for g in rec["effects"]["resolution"]}
    assert [v["resolution"] for v in ladders[()]["values"]] == [10, 16, 25, 40, 56]
    assert [v["rms_Z_table2"] for v in ladders[(("equation_of_state", "tait"),)]["values"]] == [0.20, 0.16]
    assert ladders[()]["rms_spread"] == pytest.approx(0.25)
    text = "\n".join(rec["text"])
    assert "Cheapest with RMS <= 0.15: res 16 (RMS 0.150, 2.50 s)" in text
    assert "Most accurate: res 56 (RMS 0.050, 100.00 s)" in text
    assert "around the default, largest first: resolution 0.250, dt_fraction 0.010." in text


def differ_only_in(points, axis):
    """Whether two of `points` differ in `axis` alone."""
    others = [k for k in sweep.POINT_KEYS if k != axis]
    return any(p[axis] != q[axis] and all(p[k] == q[k] for k in others) for p in points for q in points)


def test_design_varies_every_axis():
    for quick in (False, True):
        points = sweep.design(quick, backends=("numba", "vulkan"), vulkan_on_cpu=True)
        assert len({sweep.point_key(p) for p in points}) == len(points)  # no point twice
        assert all(differ_only_in(points, axis) for axis in AXES), quick
    points = sweep.design()
    for axis in set(AXES) - {"backend", "neighbour_search"}:  # one at a time around the default
        assert any(sweep.varied(p) == axis for p in points), axis
    assert DEFAULT in points
    lavapipe = sweep.design(backends=("numba", "vulkan"), vulkan_on_cpu=True)
    assert len([p for p in lavapipe if p["backend"] == "vulkan"]) == 5
    assert max(p["resolution"] for p in lavapipe if p["backend"] == "vulkan") <= 25
    gpu = sweep.design(backends=("vulkan",), vulkan_on_cpu=False)
    assert {p["backend"] for p in gpu} == {"vulkan"} and len(gpu) == len(points)


def test_sweep_command_errors_are_one_line(tmp_path, capsys):
    with pytest.raises(SystemExit):
        main(["sweep", "--out", str(tmp_path), "--backends", "numba,cuda"])
    assert "--backends" in capsys.readouterr().err
    assert main(["sweep", "--out", str(tmp_path), "--scheduler", "tcp://127.0.0.1:9", "--workers", "2"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("sphcore: error: --workers") and err.count("\n") == 1
    with pytest.raises(sweep.SweepError, match="--scheduler tcp://127.0.0.1:9: cannot reach a Dask scheduler"):
        sweep.run_sweep(tmp_path, points=[at(**TINY)], scheduler="tcp://127.0.0.1:9", timeout=1)
    (tmp_path / "sweep.json").write_text("{not json")
    assert main(["sweep", "--out", str(tmp_path), "--quick"]) == 1
    assert "sweep.json: not valid JSON" in capsys.readouterr().err
    assert (tmp_path / "sweep.json").read_text() == "{not json"  # kept as it was


def test_recommendations_per_configuration():
    rows = synthetic((13.0, 0.08, {}), (3.0, 0.12, {"resolution": 16}), (12.0, 0.04, {"config": "engineering"}),
                     (4.0, 0.09, {"resolution": 16, "config": "engineering"}),
                     (0.0, math.nan, {"config": "no_slip"}, "failed"))
    rec = recommendations(rows)
    per = {c["config"]: c for c in rec["configurations"]}
    assert set(per) == {"graphics", "engineering", "no_slip"}
    assert per["engineering"]["most_accurate"]["point"] == 2 and per["engineering"]["cheapest_meeting_threshold"]["point"] == 3
    assert per["graphics"]["most_accurate"]["point"] == 0 and per["no_slip"]["ok"] == 0
    assert sorted(per["engineering"]["on_pareto_front"]) == [2, 3] and per["graphics"]["on_pareto_front"] == [1]
    text = "\n".join(rec["text"])
    assert "Configuration engineering: 2 of 2 points ran; most accurate engineering (RMS 0.040, 12.00 s)" in text
    assert "Configuration no_slip: 0 of 1 points ran" in text
    assert sweep.point_key({k: v for k, v in at().items() if k != "config"}) == sweep.point_key(at())  # older tables


def test_pareto_plot_names_each_configuration(tmp_path, monkeypatch):
    """The picture shows which configuration each point is: a colour per configuration with its
    legend entry, a marker per other varied axis."""
    rows = synthetic((13.0, 0.08, {}), (3.0, 0.12, {"resolution": 16}), (12.0, 0.04, {"config": "engineering"}),
                     (4.0, 0.09, {"resolution": 16, "config": "engineering"}), (20.0, 0.06, {"config": "dfsph"}),
                     (0.0, math.nan, {"config": "no_slip"}, "failed"))
    seen = {}

    def capture(fig, path):
        legends = {lg.get_title().get_text(): lg for lg in fig.legends}
        by_config = legends["configuration (colour)"]
        seen["configs"] = [t.get_text() for t in by_config.get_texts()]
        seen["colours"] = [tuple(h.get_color()) for h in by_config.legend_handles]
        seen["markers"] = [t.get_text() for t in legends["varied beside it (marker)"].get_texts()]
        drawn = [(tuple(c.get_facecolor()[0][:3]), c.get_offsets()[0][0]) for c in fig.axes[0].collections]
        seen["points"] = {name: [cost for c, cost in drawn if c == tuple(col[:3])]
                          for name, col in zip(seen["configs"], seen["colours"])}

    monkeypatch.setattr(sweep, "atomic_savefig", capture)
    sweep.plot_pareto(rows, tmp_path / "pareto.png")
    assert seen["configs"] == ["graphics", "engineering", "dfsph"]  # the failed no_slip point is not drawn
    assert len(set(seen["colours"])) == 3
    assert seen["markers"] == ["default", "resolution", "Pareto front", "RMS = 0.15"]
    assert sorted(seen["points"]["engineering"]) == [4.0, 12.0] and seen["points"]["dfsph"] == [20.0]
