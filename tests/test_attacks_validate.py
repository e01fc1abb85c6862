"""Attacks on `sphcore report` and `sphcore sweep` (issue 30, section 5): damaged results files,
a missing case, a file given where a folder of results belongs, and Ctrl-C in a sweep. Each case
is the one-line refusal naming the file and what is wrong with it (exit 1, no traceback) or the
safe result it must get; a refused file is left as it was."""
import json
import os
import signal
import struct
import subprocess
import sys
import time
import zlib
from pathlib import Path

import pytest

from sphcore.cli import main
from sphcore.validate import buchner, sweep
from sphcore.validate.files import ResultsError

ROOT = Path(__file__).resolve().parents[1]
SUMMARY = {"settings": {"resolution": 20}, "rms_Z_table2": 0.0501}  # a 2D dam break read, not run
BINARY = bytes(range(128, 256)) * 4  # not UTF-8 from its first byte


def one_line_error(argv, capsys):
    """Run the CLI in this process; assert exit 1 and one line, no traceback; return the line."""
    assert main([str(a) for a in argv]) == 1
    err = capsys.readouterr().err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    return err.strip()


def png_bytes():
    """A whole 1 x 1 PNG."""
    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", 1, 1, 8, 0, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(b"\x00\x80")) + chunk(b"IEND", b""))


def results(tmp_path, files):
    """A results folder holding a readable 2D dam break summary and `files` {name: text or bytes}."""
    folder = tmp_path / "results"
    folder.mkdir()
    (folder / "dam_break_2d.json").write_text(json.dumps(SUMMARY))
    for name, content in files.items():
        path = folder / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(content if isinstance(content, bytes) else content.encode())
    return folder


CSV_HEAD = "t,front_x,column_height,T,Z,tau,H\n"
CSV_ROW = "0,0.06,0.11,0,1,0,1\n"
DAMAGED = {  # case: (files, the file named, what the message says)
    "truncated JSON": ({"dam_break_2d.json": '{"settings": {"resol'}, "dam_break_2d.json", "not valid JSON"),
    "a JSON array for a summary": ({"dam_break_2d.json": "[1, 2]"}, "dam_break_2d.json",
                                   "holds an array, not an object"),
    "text where a number belongs": ({"dam_break_2d.json": json.dumps({**SUMMARY, "rms_Z_table2": "low"})},
                                    "dam_break_2d.json", "'rms_Z_table2' is 'low', not a number"),
    "settings not an object": ({"dam_break_2d.json": json.dumps({"settings": [20]})}, "dam_break_2d.json",
                               "'settings' is '[20]', not an object"),
    "sweep table without rows": ({"sweep.json": '{"sweep": {}}'}, "sweep.json", "has no 'rows'"),
    "sweep rows not objects": ({"sweep.json": '{"sweep": {}, "rows": [1, 2]}'}, "sweep.json",
                               "'rows' is not an array of objects"),
    "binary sweep table": ({"sweep.json": BINARY}, "sweep.json", "not a text file (byte 0 is not UTF-8)"),
    "binary sweep CSV": ({"sweep.csv": BINARY}, "sweep.csv", "not a text file"),
    "recommendations an array": ({"sweep.csv": "point,status\n0,ok\n", "recommendations.json": "[]"},
                                 "recommendations.json", "holds an array, not an object"),
    "binary JSON of a section": ({"stability.json": BINARY}, "stability.json", "not a text file"),
    "truncated CSV line": ({"dam_break_2d.csv": CSV_HEAD + CSV_ROW + "0.1,0.2"}, "dam_break_2d.csv",
                           "line 3 has 2 cells, the header 7 (truncated?)"),
    "text in a plotted column": ({"dam_break_2d.csv": CSV_HEAD + CSV_ROW.replace(",0,1,0,1", ",zero,1,0,1")},
                                 "dam_break_2d.csv", "line 2: T = 'zero' is not a number"),
    "picture not a PNG": ({"spheric_test2_heights.png": b"GIF89a" + bytes(100)}, "spheric_test2_heights.png",
                          "not a PNG image"),
    "truncated picture": ({"spheric_test2_heights.png": png_bytes()[:-20]}, "spheric_test2_heights.png",
                          "a truncated PNG image"),
    "empty CSV of a convergence run": (
        {"res10/dam_break_2d.json": json.dumps({"settings": {"resolution": 10}, "rms_Z_table2": 0.2}),
         "res10/dam_break_2d.csv": "T,Z\n",
         "res20/dam_break_2d.json": json.dumps({"settings": {"resolution": 20}, "rms_Z_table2": 0.1}),
         "res20/dam_break_2d.csv": "T,Z\n0,1\n1,2\n"}, "res10/dam_break_2d.csv", "has 0 rows of data, fewer than 1"),
}


@pytest.mark.parametrize("case", DAMAGED)
def test_report_on_a_damaged_results_file(tmp_path, capsys, case):
    files, culprit, why = DAMAGED[case]
    folder = results(tmp_path, files)
    before = {p: p.read_bytes() for p in folder.rglob("*") if p.is_file()}
    line = one_line_error(["report", "--out", tmp_path / "out", "--results", folder], capsys)
    assert line.startswith(f"sphcore: error: {folder / culprit}: {why}"), line
    assert before == {p: p.read_bytes() for p in folder.rglob("*") if p.is_file()}  # nothing changed
    assert not (tmp_path / "out" / "index.html").exists()


def test_report_with_a_missing_case_says_not_run(tmp_path, capsys):
    """A folder named like a section's JSON, and a dangling link named like its picture: that section
    was not run (was: 'NoneType' object has no attribute 'stem')."""
    folder = results(tmp_path, {})
    (folder / "stability.json").mkdir()
    (folder / "stability_matrix.png").symlink_to(folder / "gone.png")
    assert main(["report", "--out", str(tmp_path / "out"), "--results", str(folder)]) == 0
    page = (tmp_path / "out" / "index.html").read_text()
    stability = page[page.index('id="stability"'):page.index('id="environment"')]
    assert "not run: <code>sphcore validate stability --out" in stability


def test_report_names_the_summaries_it_could_not_read(tmp_path, capsys):
    """The model section scans every JSON below the results folders (a run's scene.json among them):
    one it cannot read is listed on the page, not dropped in silence; the rest of the page is made."""
    folder = results(tmp_path, {"run/scene.json": '{"name": "tiny", "fluid": {', "run/other.json": BINARY,
                                "tank.json": json.dumps({"settings": {"resolution": "thirty"}, "slope_error": 0.01})})
    assert main(["report", "--out", str(tmp_path / "out"), "--results", str(folder)]) == 0
    page = (tmp_path / "out" / "index.html").read_text()
    model = page[page.index('id="model"'):page.index('id="dam_break_3d"')]
    assert "not read:" in model
    for name, why in (("scene.json", "not valid JSON"), ("other.json", "not a text file"),
                      ("tank.json", "&#x27;resolution&#x27; is &#x27;thirty&#x27;, not a number")):
        assert f"{name}</code>: {why}" in model, name
    assert "0.0501" in page  # the dam break was read


@pytest.mark.parametrize("kind", ["truncated .pvd", "no such folder"])
def test_report_results_must_be_a_folder(tmp_path, capsys, kind):
    """A file (here a truncated .pvd) or a mistyped folder as --results: refused, not silently skipped
    while the report runs the dam break itself."""
    target = tmp_path / ("tiny.pvd" if kind == "truncated .pvd" else "resluts")
    if kind == "truncated .pvd":
        target.write_text('<?xml version="1.0"?>\n<VTKFile type="Collection"><Collection><DataSet time')
    line = one_line_error(["report", "--out", tmp_path / "out", "--results", target], capsys)
    why = "not a folder" if kind == "truncated .pvd" else "no such folder"
    assert line.startswith(f"sphcore: error: --results {target}: {why}"), line
    assert not (tmp_path / "out" / "dam_break_2d.json").exists()  # nothing was run


SWEEP_TABLES = {  # sweep.json: what the message says
    "not JSON": ("{not json", "not valid JSON"),
    "no rows": ('{"sweep": {}}', "has no 'rows'"),
    "binary": (BINARY, "not a text file"),
    "a row of another kind": (json.dumps({"sweep": {}, "rows": [{"resolution": {"a": 1}}]}),
                              "row 0: 'resolution' is \"{'a': 1}\", not a number"),
}


@pytest.mark.parametrize("case", SWEEP_TABLES)
def test_sweep_over_a_damaged_table_is_refused_and_keeps_it(tmp_path, capsys, case):
    content, why = SWEEP_TABLES[case]
    path = tmp_path / "sweep.json"
    path.write_bytes(content if isinstance(content, bytes) else content.encode())
    line = one_line_error(["sweep", "--out", tmp_path, "--quick"], capsys)
    assert line.startswith(f"sphcore: error: {path}") and why in line, line
    assert path.read_bytes() == (content if isinstance(content, bytes) else content.encode())


def test_read_results_of_a_pressure_run_names_the_bad_cell(tmp_path):
    (tmp_path / "dam_break_pressure.csv").write_text("t_star,P1\n0.0,0.1\n0.1,n/a\n")
    (tmp_path / "dam_break_pressure.json").write_text("{}")
    with pytest.raises(ResultsError, match=r"dam_break_pressure.csv: line 3: P1 = 'n/a' is not a number"):
        buchner.read_results(tmp_path)


TINY_POINTS = [{"resolution": 8, "t_end": 0.01}, {"resolution": 10, "t_end": 0.3}]
TINY_SWEEP = f"""\
import sys
from sphcore.cli import main
from sphcore.validate import sweep
POINTS = [sweep.at(**p) for p in {TINY_POINTS!r}]
sweep.design = lambda quick=False, backends=("numba",), vulkan_on_cpu=True: POINTS
if __name__ == "__main__":
    sys.exit(main(["sweep", "--out", sys.argv[1]]))
"""


def test_ctrl_c_in_a_sweep_is_one_line_and_it_runs_again(tmp_path):
    """Ctrl-C at a terminal reaches the whole process group, the Dask workers too (they printed
    tracebacks in 2 of 3 tries). Twice over: a sweep whose first point is done (in sweep.json) gets
    SIGINT to its group once its points are submitted; it exits 130 with one line and no traceback,
    and the next try starts again from the table, which still holds that point."""
    script = tmp_path / "tiny_sweep.py"
    script.write_text(TINY_SWEEP)
    out = tmp_path / "sweep"
    first = sweep.at(**TINY_POINTS[0])
    out.mkdir()
    sweep.write_table(out, [{**first, "point": 0, "varied": sweep.varied(first), "status": "ok", "wall_s": 0.125,
                             "rms_Z_table2": 0.5}], {})
    env = {**os.environ, "OMP_WAIT_POLICY": "passive"}
    for attempt in range(2):
        err_path = tmp_path / f"stderr{attempt}"
        with open(err_path, "w") as err:
            proc = subprocess.Popen([sys.executable, str(script), str(out)], cwd=ROOT, env=env, stdout=subprocess.PIPE,
                                    stderr=err, start_new_session=True,
                                    preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
            deadline = time.monotonic() + 180  # a loaded machine: the cluster may take long to start
            while "sweep:" not in err_path.read_text() and proc.poll() is None and time.monotonic() < deadline:
                time.sleep(0.1)  # the progress bar: the cluster is up and the point submitted
            assert proc.poll() is None, err_path.read_text()
            os.killpg(proc.pid, signal.SIGINT)  # what a terminal's Ctrl-C does
            proc.communicate(timeout=120)
        text = err_path.read_text()
        lines = [line for line in text.replace("\r", "\n").splitlines() if line.strip()]
        assert proc.returncode == 130, text
        assert "Traceback" not in text and "KeyboardInterrupt" not in text and "distributed" not in text, text
        assert lines[-1] == (f"sphcore: interrupted; 1 of 2 points done, written to {out}/sweep.csv and sweep.json "
                             "(the same command runs the rest)"), text
        assert all(line.startswith("sweep:") for line in lines[:-1]), text  # beside it only the progress bar
        stored = json.loads((out / "sweep.json").read_text())
        assert [(r["point"], r["status"], r["wall_s"]) for r in stored["rows"]] == [(0, "ok", 0.125)]
        assert stored["sweep"]["reused"] == 1
