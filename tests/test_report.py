"""The HTML report (`sphcore report`): its sections, the numbers of the files it read, "not run"
with the command for what is missing, versions and hardware, pictures that exist; and the 2D dam
break run into the folder where it is missing."""
import json
import os
import platform
import re

import numba
import numpy as np
import pytest

from sphcore.cli import main
from sphcore.validate import report, sweep
from sphcore.validate.dam_break import SETTINGS, write_csv


def images(page, folder):
    """The <img> sources of `page`, each checked to be a file in `folder`."""
    sources = re.findall(r'<img src="([^"]+)"', page)
    assert all((folder / s).is_file() and (folder / s).stat().st_size > 1000 for s in sources), sources
    return sources


def write_results(folder):
    """A results folder as the other commands leave it, with numbers no run would give."""
    folder.mkdir()
    rows = [{"t": t, "front_x": 0.25 + t, "column_height": 0.5 - t / 2, "T": t * 8.86, "Z": 1 + 4 * t,
             "tau": t * 6.26, "H": 1 - t} for t in np.linspace(0.0, 0.5, 11)]
    write_csv(folder / "dam_break_2d.csv", rows)
    summary = {"settings": {**SETTINGS, "resolution": 37}, "particles": 2738, "dt": 1.234e-4, "steps": 4052,
               "wall_s": 41.7, "min_neighbours": 3, "gate_shift_T": 0.175, "rms_Z_table2": 0.0876543,
               "points_table2": 14, "rms_Z_table2_unshifted": 0.2468, "best_shift_T_table2": 0.19,
               "rms_Z_koshizuka": 0.1357, "points_koshizuka": 8, "rms_Z_koshizuka_unshifted": 0.3579}
    (folder / "dam_break_2d.json").write_text(json.dumps(summary))
    table = [{**sweep.at(resolution=r), "point": i, "varied": "resolution", "status": "ok", "wall_s": 0.7 * r,
              "rms_Z_table2": 0.9 / r, "steps": 100 * r, "particles": 2 * r * r} for i, r in enumerate((10, 20))]
    table.append({**sweep.at(dt_fraction=2.0), "point": 2, "varied": "dt_fraction", "status": "failed",
                  "error": "SimulationError: blow-up by step 77"})
    sweep.write_table(folder, table, {"workers": 1})
    sweep.write_outputs(folder, table)
    stability = [{"name": "dt_10x_bound", "status": "detected", "step": 1234, "particle": 56, "cause": "time step",
                  "message": "blow-up by step 1234"}, {"name": "one_particle", "status": "stable", "step": 300}]
    (folder / "stability.json").write_text(json.dumps(stability))
    (folder / "stability.csv").write_text("name,status\ndt_10x_bound,detected\none_particle,stable\n")
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1])
    fig.savefig(folder / "spheric_test2_heights.png")
    plt.close(fig)


def test_report_shows_what_it_read(tmp_path, capsys):
    results, out = tmp_path / "results", tmp_path / "report"
    write_results(results)
    (tmp_path / "empty").mkdir()
    other = tmp_path / "other"
    other.mkdir()
    (other / "dam_break_2d.json").write_text(json.dumps({"settings": {"resolution": 160, "backend": "vulkan"},
                                                         "rms_Z_table2": 0.0975319, "particles": 51200}))
    assert main(["report", "--out", str(out), "--results", str(tmp_path / "empty"), "--results", str(results),
                 "--results", str(other)]) == 0
    assert capsys.readouterr().out.strip() == f"wrote {out / 'index.html'}"
    page = (out / "index.html").read_text()

    for anchor in ("dam_break_2d", "sweep", "dam_break_3d", "spheric_test2", "stability", "environment"):
        assert f'<h2 id="{anchor}">' in page
    # the 2D dam break: its numbers, settings, the picture drawn from its CSV
    for number in ("0.08765", "0.2468", "0.1357", "2738", "4052", "41.7", "<td>37</td>"):
        assert number in page, number
    assert "<td>160</td>" in page and "<td>0.09753</td>" in page and "<td>51200</td>" in page  # another run
    # the sweep: recommendations and table; a failed point with its error
    assert "Cheapest with RMS &lt;= 0.15: res 10 (RMS 0.090, 7.00 s)" in page
    assert "SimulationError: blow-up by step 77" in page
    # other sections: a JSON list as a table, a PNG by prefix, "not run" with the command
    assert "<td>1234</td>" in page and "dt_10x_bound" in page and "stability.csv" in page
    assert "not run: <code>sphcore validate dam-break --dimension 3 --out" in page
    assert sorted(images(page, out)) == ["dam_break_2d.png", "pareto.png", "spheric_test2_heights.png"]
    # versions and hardware
    for text in (f">{np.__version__}</td>", f">{numba.__version__}</td>", platform.python_version(),
                 f"<td>{os.cpu_count()}</td>", report.cpu_model()):
        assert text in page, text
    devices = report.vulkan_devices()
    assert (devices[0]["name"] if isinstance(devices, list) else devices) in page


def test_report_runs_the_dam_break_where_it_is_missing(tmp_path, monkeypatch):
    """The run itself is tested in test_validation.py; here a stand-in with the same outputs, so
    that this test does not pay numba's compilation."""
    from sphcore.validate import dam_break
    calls = []

    def run(settings, out_dir, progress=True):
        calls.append((settings, out_dir))
        rows = [{"t": t, "front_x": 0.25, "column_height": 0.5, "T": t, "Z": 1.0, "tau": t, "H": 1.0} for t in (0.0, 0.1)]
        summary = {"settings": {**dam_break.SETTINGS, **settings}, "particles": 4321, "steps": 2, "dt": 0.05,
                   "wall_s": 0.5, "gate_shift_T": 0.175, "rms_Z_table2": 0.0654321}
        write_csv(out_dir / "dam_break_2d.csv", rows)
        (out_dir / "dam_break_2d.json").write_text(json.dumps(summary))
        return rows, summary

    monkeypatch.setattr(dam_break, "run_dam_break", run)
    path = report.build_report(tmp_path, settings={"resolution": 8})
    assert calls == [({"resolution": 8}, tmp_path)]
    page = path.read_text()
    assert "Run by this report" in page and "<td>4321</td>" in page and "<td>0.06543</td>" in page
    assert images(page, tmp_path) == ["dam_break_2d.png"]
    assert page.count('class="missing">not run') == 4  # the sweep, 3D, SPHERIC, stability
    # a second report reads what the first one ran
    report.build_report(tmp_path)
    assert len(calls) == 1 and "Read from" in path.read_text()


def test_front_convergence_measures_the_differences_between_resolutions(tmp_path):
    """Fronts Z(T) = 1 + T + 0.8 sin(T) / resolution at 20, 40 and 80: successive RMS differences halve
    (observed order 1), the coarsest's distance from the finest is the sum of the steps; a run that
    stopped early, or a configuration at one resolution, gives no row."""
    from sphcore.validate.report import front_convergence

    runs = []
    T = np.linspace(0.0, 3.0, 301)
    for config, resolutions in (("engineering", (20, 40, 80)), ("graphics", (40,))):
        for resolution in resolutions:
            folder = tmp_path / f"{config}_{resolution}"
            folder.mkdir()
            Z = 1 + T + 0.8 * np.sin(T) / resolution
            (folder / "dam_break_2d.csv").write_text("T,Z\n" + "".join(f"{t},{z}\n" for t, z in zip(T, Z)))
            summary = {"settings": {"config": config, "resolution": resolution, "backend": "numba"},
                       "rms_Z_table2": 0.1, "error": None}
            runs.append((folder / "dam_break_2d.json", summary))
    runs.append((tmp_path / "stopped" / "dam_break_2d.json", {"settings": {"config": "engineering", "resolution": 160},
                                                              "rms_Z_table2": 0.1, "error": "blow-up at step 9"}))
    rows = front_convergence(runs)
    assert [r["resolutions"] for r in rows] == ["20 -> 40", "40 -> 80"]
    sine = 0.8 * np.sqrt(np.mean(np.sin(np.linspace(0.0, 3.0, 200)) ** 2))
    assert rows[0]["RMS of Z between them"] == pytest.approx(sine * (1 / 20 - 1 / 40), rel=1e-3)
    assert rows[1]["RMS of Z between them"] == pytest.approx(sine * (1 / 40 - 1 / 80), rel=1e-3)
    assert rows[0]["finest"] == 80
    assert rows[0]["RMS of Z from the finest"] == pytest.approx(sine * (1 / 20 - 1 / 80), rel=1e-3)
    assert rows[0]["observed order"] is None and rows[1]["observed order"] == pytest.approx(1.0, abs=1e-3)
