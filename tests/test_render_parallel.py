"""`sphcore render` of a run of the MPI driver: its .pvd lists parallel snapshots NAME_NNNNNNN.pvtp, each
naming one piece NAME_NNNNNNN_pR.vtp a rank, and (resumed on one rank) plain NAME_NNNNNNN.vtp after them.
The run folders are written by hand, as sphcore.parallel writes them (write_vtp a piece, add_parallel)."""
import xml.etree.ElementTree as ET

import numpy as np
import pytest

pv = pytest.importorskip("pyvista")

from sphcore.cli import main  # noqa: E402
from sphcore.output import SnapshotSeries, pvd_bytes, write_vtp  # noqa: E402
from sphcore.render import load_run, read_positions, render_run  # noqa: E402
from sphcore.scene import Scene, SceneError  # noqa: E402
from test_render import error_line, foreground, read_png  # noqa: E402

NAME = "droplet_3d"


def block(shift=0.0):
    """8 x 8 x 8 particles at the scene's spacing (0.01 m) about the box's centre, moved `shift` along x."""
    g = 0.11 + (np.arange(8) + 0.5) * 0.01
    return np.array([[x + shift, y, z] for x in g for y in g for z in g], np.float32)


def arrays(x):
    """The point data the driver writes with a piece."""
    n = len(x)
    return {"velocity": np.zeros((n, 3), np.float32), "density": np.full(n, 1000.0, np.float32),
            "pressure": np.zeros(n, np.float32)}


def split(x, seed=0):
    """x's particles as two ranks hold them: x below the block's middle and the rest, each shuffled."""
    low = x[:, 0] < np.median(x[:, 0])
    rng = np.random.default_rng(seed)
    return [rng.permutation(x[low]), rng.permutation(x[~low])]


def add_parallel(series, step, t, parts):
    """Snapshot `step` as the driver writes it: each rank's piece, then rank 0's .pvtp naming them."""
    for rank, part in enumerate(parts):
        write_vtp(series.out_dir / series.piece_names(step, len(parts))[rank], part, arrays(part))
    return series.add_parallel(step, t, len(parts), parts[0], arrays(parts[0]))


def rows(x):
    """The rows of x, sorted: two sets of particles compared regardless of order."""
    return sorted(map(tuple, np.asarray(x).tolist()))


@pytest.fixture
def run(tmp_path):
    """A run folder of droplet_3d whose one snapshot (step 0) is the block in 2 pieces."""
    folder = tmp_path / "run"
    folder.mkdir()
    (folder / "scene.json").write_text(Scene.load(NAME).to_json())
    add_parallel(SnapshotSeries(folder, NAME), 0, 0.0, split(block()))
    return folder


def test_pvtp_positions_are_its_pieces_joined(run):
    pvtp = run / f"{NAME}_0000000.pvtp"
    sources = [p.get("Source") for p in ET.parse(pvtp).getroot().iter("Piece")]
    assert sources == [f"{NAME}_0000000_p0.vtp", f"{NAME}_0000000_p1.vtp"]
    parts = [pv.read(run / s).points for s in sources]
    assert len(parts[0]) == len(parts[1]) == 256
    x = read_positions(pvtp)
    assert x.shape == (512, 3) and x.dtype == np.float32
    assert rows(x) == rows(block()) == rows(np.concatenate(parts))
    # the .pvd lists the .pvtp alone; without it, the .pvtp is found by name and its pieces are no snapshots
    assert [p.name for p in load_run(run)[1]] == [pvtp.name]
    (run / f"{NAME}.pvd").unlink()
    assert [p.name for p in load_run(run)[1]] == [pvtp.name]


def test_render_parallel_run(run, tmp_path):
    out = tmp_path / "frames"
    written = render_run(run, out, progress=False)
    stem = f"{NAME}_surface_0000000"
    assert [p.name for p in written] == [f"{stem}.vtp", f"{stem}.png", f"{NAME}_surface.pvd"]
    assert sorted(p.name for p in out.iterdir()) == sorted(p.name for p in written)
    # the surface wraps the whole block, both ranks' halves (one piece alone would end at the middle in x)
    mesh = pv.read(out / f"{stem}.vtp")
    lo, hi = block().min(axis=0), block().max(axis=0)
    assert mesh.n_cells > 0
    assert np.all(np.array(mesh.bounds[0::2]) < lo) and np.all(np.array(mesh.bounds[1::2]) > hi), mesh.bounds
    assert np.all(np.array(mesh.bounds[0::2]) > lo - 0.02) and np.all(np.array(mesh.bounds[1::2]) < hi + 0.02)
    img = read_png(out / f"{stem}.png")
    assert img.shape == (768, 1024, 3) and 0.01 < foreground(img).mean() < 0.5
    # the command too
    assert main(["render", str(run), "--out", str(tmp_path / "cli")]) == 0
    assert (tmp_path / "cli" / f"{stem}.png").is_file()


def test_missing_or_damaged_piece_names_it(run, tmp_path, capsys):
    pvtp = run / f"{NAME}_0000000.pvtp"
    piece = run / f"{NAME}_0000000_p1.vtp"
    data = piece.read_bytes()
    piece.unlink()
    with pytest.raises(SceneError, match=f"{pvtp}: its piece {piece.name} is missing") as e:
        read_positions(pvtp)
    assert "\n" not in str(e.value)
    err = error_line(capsys, "render", run, "--out", tmp_path / "o1")
    assert str(pvtp) in err and piece.name in err
    assert not (tmp_path / "o1").exists()  # found before the first frame was drawn
    piece.write_bytes(data[:3000])  # truncated
    err = error_line(capsys, "render", run, "--out", tmp_path / "o2")
    assert f"{pvtp}: piece {piece}: not a readable snapshot, truncated" in err
    assert not (tmp_path / "o2").exists()
    with pytest.raises(SceneError, match=f"{pvtp}: piece {piece}: not a readable snapshot"):
        read_positions(pvtp)


def test_resumed_on_one_rank_renders_both_kinds_in_step_order(run, tmp_path):
    """A .pvd listing the .pvtp of step 0 and, resumed on one rank, the .vtp of step 10 (listed first here, so
    that only the steps give the order): both rendered, in step order, the later one where its block moved."""
    series = SnapshotSeries(run, NAME)
    add_parallel(series, 5, 0.001, split(block(), seed=1))
    series.add(10, 0.002, block(0.05), arrays(block()))
    (run / f"{NAME}.pvd").write_bytes(pvd_bytes([(f"{NAME}_0000010.vtp", 0.002), (f"{NAME}_0000000.pvtp", 0.0),
                                                 (f"{NAME}_0000005.pvtp", 0.001)]))
    assert [p.name for p in load_run(run)[1]] == [f"{NAME}_0000000.pvtp", f"{NAME}_0000005.pvtp",
                                                  f"{NAME}_0000010.vtp"]
    out = tmp_path / "frames"
    written = render_run(run, out, progress=False)
    stems = [f"{NAME}_surface_{s:07d}" for s in (0, 5, 10)]
    assert [p.name for p in written] == [f"{s}.{e}" for s in stems for e in ("vtp", "png")] + [f"{NAME}_surface.pvd"]
    series_out = ET.parse(out / f"{NAME}_surface.pvd").getroot()
    assert [(ds.get("file"), float(ds.get("timestep"))) for ds in series_out.iter("DataSet")] == [
        (f"{stems[0]}.vtp", 0.0), (f"{stems[1]}.vtp", 0.001), (f"{stems[2]}.vtp", 0.002)]
    centres = [np.mean(pv.read(out / f"{s}.vtp").points[:, 0]) for s in stems]
    assert abs(centres[0] - 0.15) < 0.005 and abs(centres[1] - 0.15) < 0.005 and abs(centres[2] - 0.2) < 0.005
    # without the .pvd: found by name, the same order, no piece taken for a snapshot
    (run / f"{NAME}.pvd").unlink()
    written = render_run(run, tmp_path / "again", progress=False)
    assert [p.name for p in written] == [f"{s}.{e}" for s in stems for e in ("vtp", "png")]
