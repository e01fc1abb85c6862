"""Attacks, third round: files that sphcore did not write (issue 30, section 3, and plot and --resume
from section 5). Each case is an input and the one-line refusal, or the safe result, it must get.

- a run writes and deletes only what its manifest (sphcore-run.json) lists: a user's scene.json,
  ParaView state, experiment .vtp or final.png is never replaced, deleted or adopted;
- a folder of an earlier sphcore (no manifest) is refused, --overwrite included, and adopted by
  --resume;
- a folder deleted and recreated under a running run stops it, and nothing of it lands in the new one;
- plot writes only PNGs of its own, blames the missing folder of --out, never suggests unpickling,
  and refuses a final state older than the checkpoint; a resume deletes the earlier final state;
- the advice for a folder of snapshots with no checkpoint is not circular;
- --resume with an edited scene names the key that differs.
"""
import json
import os
import shutil
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from sphcore import folder, output
from sphcore.cli import main
from sphcore.folder import MANIFEST
from sphcore.simulation import CHECKPOINT
from test_attacks import TOML, loadable, one_line_error

KEEP = {"paraview_state.pvd": b"<VTKFile type='Collection'/>", "experiment_2024001.vtp": b"<VTKFile/>",
        "final.png": b"my own picture", "notes.txt": b"mine"}


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """A scene file (48 particles, 20 steps, snapshots every 5, checkpoints every 10) and a finished run of it."""
    base = tmp_path_factory.mktemp("tiny")
    (base / "tiny.toml").write_text(TOML)
    assert main(["run", str(base / "tiny.toml"), "--out", str(base / "run")]) == 0
    return base


def stopped_error(argv, capsys):
    """Run the CLI in this process; assert it stopped mid-run (exit 1) with one `sphcore:` line after the
    progress bar, no traceback; return that line."""
    assert main([str(a) for a in argv]) == 1
    err = capsys.readouterr().err
    assert "Traceback" not in err and err.count("sphcore:") == 1, err
    return err.strip().splitlines()[-1].split("\r")[-1]


def copy_run(tiny, tmp_path):
    out = tmp_path / "run"
    shutil.copytree(tiny / "run", out)
    return out


def contents(out_dir):
    return {p.name: p.read_bytes() for p in sorted(out_dir.iterdir())}


def manifest(out_dir):
    return set(json.loads((out_dir / MANIFEST).read_text())["files"])


def test_a_run_lists_what_it_wrote(tiny):
    out = tiny / "run"
    assert manifest(out) == {"scene.json", CHECKPOINT, "final.npz", "tiny.pvd"} | {
        f"tiny_{k:07d}.vtp" for k in (0, 5, 10, 15, 20)}
    assert manifest(out) == {p.name for p in out.iterdir()} - {MANIFEST}


def test_users_scene_json_is_never_replaced(tiny, tmp_path, capsys):
    out = tmp_path / "mine"
    out.mkdir()
    (out / "scene.json").write_text('{"my": "scene"}')
    for extra in ([], ["--overwrite"]):
        err = one_line_error(["run", tiny / "tiny.toml", "--out", out, *extra], capsys)
        assert f"{out}: scene.json in the way: no sphcore run wrote it" in err, err
        assert "--overwrite included: move them away, or give another --out" in err
        assert (out / "scene.json").read_text() == '{"my": "scene"}'
        assert sorted(p.name for p in out.iterdir()) in (["scene.json"], [MANIFEST, "scene.json"])
        assert not (out / CHECKPOINT).exists()


def test_overwrite_deletes_only_the_manifests_files_and_says_what_it_kept(tiny, tmp_path, capsys):
    out = copy_run(tiny, tmp_path)
    for name, data in KEEP.items():
        (out / name).write_bytes(data)
    shorter = tmp_path / "shorter.toml"
    shorter.write_text(TOML.replace("steps = 20", "steps = 5"))
    assert main(["run", str(shorter), "--out", str(out), "--overwrite"]) == 0
    err = capsys.readouterr().err
    assert (f"sphcore: --overwrite: deleted 9 files of the earlier run in {out}; kept 4 it did not write: "
            "experiment_2024001.vtp, final.png, notes.txt, paraview_state.pvd") in err, err
    for name, data in KEEP.items():
        assert (out / name).read_bytes() == data, name
    assert sorted(p.name for p in out.glob("tiny_*.vtp")) == ["tiny_0000000.vtp", "tiny_0000005.vtp"]
    assert manifest(out) == {"scene.json", CHECKPOINT, "final.npz", "tiny.pvd", "tiny_0000000.vtp", "tiny_0000005.vtp"}
    assert int(np.load(out / "final.npz")["step"]) == 5


def test_a_forged_manifest_deletes_nothing_outside_a_runs_names(tiny, tmp_path, capsys):
    """The manifest is untrusted: only plain names of a run's files are taken from it."""
    out = copy_run(tiny, tmp_path)
    (tmp_path / "precious.txt").write_text("keep")
    (out / "notes.txt").write_text("keep")
    listed = json.loads((out / MANIFEST).read_text())
    listed["files"] += ["../precious.txt", "notes.txt", "/etc/hostname"]
    (out / MANIFEST).write_text(json.dumps(listed))
    assert main(["run", str(tiny / "tiny.toml"), "--out", str(out), "--overwrite", "--steps", "5"]) == 0
    capsys.readouterr()
    assert (tmp_path / "precious.txt").read_text() == "keep" and (out / "notes.txt").read_text() == "keep"


def test_folder_of_an_earlier_sphcore_is_refused_and_overwrite_deletes_nothing(tiny, tmp_path, capsys):
    """No manifest: today's names of a run are files in the way, --overwrite or not."""
    out = copy_run(tiny, tmp_path)
    (out / MANIFEST).unlink()
    before = contents(out)
    err = one_line_error(["run", tiny / "tiny.toml", "--out", out, "--overwrite"], capsys)
    assert f"{out}: checkpoint.npz, final.npz, scene.json and 6 more in the way: no sphcore run wrote them" in err, err
    assert contents(out) == before


def test_resume_adopts_a_folder_of_an_earlier_sphcore(tiny, tmp_path, capsys):
    out = copy_run(tiny, tmp_path)
    (out / MANIFEST).unlink()
    (out / "paraview_state.pvd").write_bytes(KEEP["paraview_state.pvd"])
    assert main(["run", "--resume", str(out), "--steps", "25"]) == 0
    capsys.readouterr()
    assert manifest(out) == {"scene.json", CHECKPOINT, "final.npz", "tiny.pvd"} | {
        f"tiny_{k:07d}.vtp" for k in (0, 5, 10, 15, 20, 25)}
    assert int(np.load(out / "final.npz")["step"]) == 25
    assert (out / "paraview_state.pvd").read_bytes() == KEEP["paraview_state.pvd"]


def test_series_never_adopts_a_users_vtp(tiny, tmp_path, capsys):
    """A user's NAME.pvd stops a new run; an entry added to the run's own .pvd by hand is dropped on
    resume (its .vtp is left alone); a user's NAME_NNNNNNN.vtp stops the run naming it."""
    out = tmp_path / "mine"
    out.mkdir()
    (out / "tiny.pvd").write_text('<VTKFile type="Collection"><Collection><DataSet timestep="-1" '
                                  'file="experiment_2024001.vtp"/></Collection></VTKFile>')
    (out / "experiment_2024001.vtp").write_bytes(KEEP["experiment_2024001.vtp"])
    err = one_line_error(["run", tiny / "tiny.toml", "--out", out], capsys)
    assert f"{out}: tiny.pvd in the way" in err, err

    out = copy_run(tiny, tmp_path)
    assert main(["run", str(tiny / "tiny.toml"), "--out", str(out), "--overwrite", "--steps", "10"]) == 0
    pvd = ET.parse(out / "tiny.pvd")
    ET.SubElement(pvd.getroot().find("Collection"), "DataSet", timestep="-1", file="experiment_2024001.vtp")
    pvd.write(out / "tiny.pvd")
    (out / "experiment_2024001.vtp").write_bytes(KEEP["experiment_2024001.vtp"])
    assert main(["run", "--resume", str(out), "--steps", "15"]) == 0
    capsys.readouterr()
    listed = [ds.get("file") for ds in ET.parse(out / "tiny.pvd").getroot().iter("DataSet")]
    assert listed == [f"tiny_{k:07d}.vtp" for k in (0, 5, 10, 15)]
    assert (out / "experiment_2024001.vtp").read_bytes() == KEEP["experiment_2024001.vtp"]
    loadable(out)

    (out / "tiny_0000020.vtp").write_bytes(b"an experiment's")  # where the resumed run's next snapshot goes
    err = one_line_error(["run", "--resume", out, "--steps", "20"], capsys)
    assert f"{out}: tiny_0000020.vtp in the way: no sphcore run wrote it" in err, err
    assert (out / "tiny_0000020.vtp").read_bytes() == b"an experiment's"


def test_folder_replaced_under_a_running_run(tiny, tmp_path, capsys, monkeypatch):
    """Run A's folder is deleted and made again, and run B locks the new one: A stops at its next
    write with one line naming the folder, and writes nothing into B's folder."""
    out = tmp_path / "run"
    real_add, calls, b_lock = output.SnapshotSeries.add, [], []

    def add(self, *args, **kw):
        calls.append(1)
        if len(calls) == 2:  # the snapshot of step 5
            shutil.rmtree(out)
            b_lock.append(folder.lock(out))  # run B
            (out / "scene.json").write_text("B's")
        return real_add(self, *args, **kw)

    monkeypatch.setattr(output.SnapshotSeries, "add", add)
    try:
        err = stopped_error(["run", tiny / "tiny.toml", "--out", out], capsys)
    finally:
        os.close(b_lock[0])
    assert f"{out}: the folder this run locked was deleted or replaced while it ran; stopped" in err, err
    assert contents(out) == {"scene.json": b"B's"}


def test_check_sees_a_folder_removed(tmp_path):
    with folder.RunFolder(tmp_path / "run") as run_folder:
        run_folder.write_bytes("scene.json", b"{}")
        (tmp_path / "run").rename(tmp_path / "moved")
        with pytest.raises(folder.FolderError, match="deleted or replaced while it ran"):
            run_folder.write_bytes("final.npz", b"x")
    assert sorted(p.name for p in (tmp_path / "moved").iterdir()) == sorted([MANIFEST, "scene.json"])


def test_snapshots_without_checkpoint_give_advice_that_works(tiny, tmp_path, capsys):
    out = copy_run(tiny, tmp_path)
    (out / CHECKPOINT).unlink()
    (out / "final.npz").unlink()
    err = one_line_error(["run", "--resume", out], capsys)
    assert f"{out / CHECKPOINT}: no such file: {out} holds a run that wrote no checkpoint, so it cannot be " \
           f"resumed; start it again with `sphcore run SCENE --out {out} --overwrite`" in err, err
    err = one_line_error(["run", tiny / "tiny.toml", "--out", out], capsys)
    assert f"{out} holds a run that wrote no checkpoint, so it cannot be resumed: replace it with --overwrite" in err
    assert "--resume" not in err
    assert main(["run", str(tiny / "tiny.toml"), "--out", str(out), "--overwrite"]) == 0  # the advice works
    capsys.readouterr()
    assert int(np.load(out / "final.npz")["step"]) == 20


def test_resume_deletes_the_earlier_final_state(tiny, tmp_path, capsys, monkeypatch):
    """A finished run at step 20 resumed to 40 and stopped at 30 keeps no final.npz of step 20 (nor its
    picture); plot says there is no final state."""
    pytest.importorskip("matplotlib")
    out = copy_run(tiny, tmp_path)
    assert main(["plot", str(out)]) == 0
    assert "final.png" in manifest(out)
    real_add = output.SnapshotSeries.add

    def add(self, step, *args, **kw):
        if step == 30:
            raise MemoryError("stopped here")
        return real_add(self, step, *args, **kw)

    monkeypatch.setattr(output.SnapshotSeries, "add", add)
    err = stopped_error(["run", "--resume", out, "--steps", 40], capsys)
    assert "out of memory at step 30 (stopped here)" in err, err
    assert int(np.load(out / CHECKPOINT)["step"]) == 20 and not (out / "final.npz").exists()
    assert not (out / "final.png").exists()
    err = one_line_error(["plot", out], capsys)
    assert f"{out / 'final.npz'}: no such file" in err


def test_plot_refuses_a_final_state_older_than_the_checkpoint(tiny, tmp_path, capsys):
    """A folder of an earlier sphcore, resumed and stopped: final.npz of step 10 beside checkpoint.npz of step 20."""
    pytest.importorskip("matplotlib")
    out = copy_run(tiny, tmp_path)
    assert main(["run", str(tiny / "tiny.toml"), "--out", str(tmp_path / "ten"), "--steps", "10"]) == 0
    capsys.readouterr()
    shutil.copy(tmp_path / "ten" / "final.npz", out / "final.npz")
    err = one_line_error(["plot", out], capsys)
    assert (f"{out / 'final.npz'}: the final state of step 10, older than checkpoint.npz beside it (step 20): "
            f"the run was resumed and stopped before its end; finish it with `sphcore run --resume {out}`") in err
    assert not (out / "final.png").exists()


@pytest.mark.parametrize("target", ["final.npz", "scene.json", CHECKPOINT, "tiny_0000020.vtp", "tiny.pvd"])
def test_plot_never_replaces_a_runs_file(tiny, tmp_path, capsys, target):
    out = copy_run(tiny, tmp_path)
    before = contents(out)
    err = one_line_error(["plot", out, "--out", out / target], capsys)
    assert f"{out / target}: not a .png name; `sphcore plot` writes PNG pictures and replaces nothing else" in err
    assert contents(out) == before


def test_plot_replaces_only_a_picture_of_its_own(tiny, tmp_path, capsys):
    pytest.importorskip("matplotlib")
    out = copy_run(tiny, tmp_path)
    mine = tmp_path / "holiday.png"
    mine.write_bytes(b"\x89PNG\r\n\x1a\n" + b"a photo")
    err = one_line_error(["plot", out, "--out", mine], capsys)
    assert f"{mine}: exists and is not a picture `sphcore plot` drew; it is never replaced" in err
    assert mine.read_bytes() == b"\x89PNG\r\n\x1a\n" + b"a photo"
    (out / "final.png").write_bytes(b"my own picture")  # in the run's folder, unlisted
    err = one_line_error(["plot", out], capsys)
    assert f"{out / 'final.png'}: exists and is not a picture `sphcore plot` drew" in err
    assert (out / "final.png").read_bytes() == b"my own picture"
    picture = tmp_path / "picture.png"
    for _ in range(2):  # its own picture, drawn again
        assert main(["plot", str(out), "--out", str(picture)]) == 0
    assert picture.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_plot_blames_the_missing_folder_of_out(tiny, tmp_path, capsys):
    out = copy_run(tiny, tmp_path)
    err = one_line_error(["plot", out, "--out", tmp_path / "missing" / "dir" / "x.png"], capsys)
    assert err == f"sphcore: error: {tmp_path / 'missing' / 'dir'}: no such folder (the folder of --out " \
                  f"{tmp_path / 'missing' / 'dir' / 'x.png'})"


@pytest.mark.parametrize("content", ["random", "npy", "objects", "no position"])
def test_plot_of_a_damaged_final_state_never_suggests_unpickling(tiny, tmp_path, capsys, content):
    out = copy_run(tiny, tmp_path)
    final = out / "final.npz"
    if content == "random":
        final.write_bytes(np.random.default_rng(1).bytes(5000))
        says = "not an .npz archive"
    elif content == "npy":
        np.save(open(final, "wb"), np.arange(5))
        says = "not an .npz archive"
    elif content == "objects":
        np.savez(final, position=np.array([None, 1], object), velocity=np.zeros((2, 2)), time=0.0, scene="{}")
        says = "member 'position' holds Python objects, which are never loaded"
    else:
        np.savez(final, velocity=np.zeros((2, 2)))
        says = "no member 'position'"
    err = one_line_error(["plot", out], capsys)
    assert err == f"sphcore: error: {final}: not a readable final state ({says})", err
    assert "pickle" not in err


def test_resume_with_an_edited_scene_names_the_key(tiny, tmp_path, capsys):
    out = copy_run(tiny, tmp_path)
    edited = tmp_path / "edited.toml"
    edited.write_text(TOML.replace("dt = 1e-3", "dt = 2e-3").replace("model = \"graphics\"", "model = \"graphics\"\n"
                                                                      "viscosity = false"))
    before = contents(out)
    err = one_line_error(["run", "--resume", out, edited], capsys)
    assert (f"{edited} is not the scene of the run in {out} (its scene.json): physics.viscosity: false in "
            f"{edited}, true in the run; time.dt: 0.002 in {edited}, 0.001 in the run; leave SCENE out") in err, err
    assert contents(out) == before


def test_overwrite_patterns_are_in_run_help(capsys):
    with pytest.raises(SystemExit):
        main(["run", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert f"the files its manifest ({MANIFEST}) lists are deleted, only under a run's names (checkpoint.npz, " \
           "final.npz, final.png, profile.json, scene.json, walls.vtp, NAME.pvd, NAME_NNNNNNN.vtp, NAME_NNNNNNN.pvtp, " \
           "NAME_NNNNNNN_pR.vtp, gauges/NAME.csv, gauges.png); " \
           "files it did not write " \
           "are kept" in text


def test_profile_json_of_the_users_stops_the_run_before_it_starts(tiny, tmp_path, capsys):
    out = tmp_path / "mine"
    out.mkdir()
    (out / "profile.json").write_text("{}")
    err = one_line_error(["run", tiny / "tiny.toml", "--out", out, "--profile"], capsys)
    assert f"{out / 'profile.json'}: a file no sphcore run wrote" in err
    assert sorted(p.name for p in out.iterdir()) == ["profile.json"]


def test_render_into_the_runs_folder_is_refused(tiny, tmp_path, capsys):
    pytest.importorskip("pyvista")
    out = copy_run(tiny, tmp_path)
    before = contents(out)
    err = one_line_error(["render", out, "--out", out], capsys)
    assert f"--out {out}: a run's folder; `sphcore render` writes its meshes and pictures into a folder of" in err
    assert contents(out) == before
