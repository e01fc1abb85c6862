"""sphcore.output, checked against the real VTK XML reader (pip install vtk)."""
import os
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from sphcore import output
from sphcore.output import SnapshotSeries, atomic_savez, atomic_write_bytes, write_vtp

vtk = pytest.importorskip("vtk")
from vtk.util.numpy_support import vtk_to_numpy  # noqa: E402


def read_vtp(path):
    reader = vtk.vtkXMLPolyDataReader()
    reader.SetFileName(str(path))
    reader.Update()
    assert reader.GetErrorCode() == 0
    return reader.GetOutput()


def particles(n, seed=0):
    rng = np.random.default_rng(seed)
    pos = rng.random((n, 2), dtype=np.float32)
    return pos, {
        "density": rng.random(n, dtype=np.float32) * 1000,
        "velocity": rng.standard_normal((n, 2)).astype(np.float32),
        "id": np.arange(n, dtype=np.int32),
        "pressure64": rng.standard_normal(n),
    }


def test_vtp_roundtrip_2d(tmp_path):
    n = 257
    pos, data = particles(n)
    path = tmp_path / "p.vtp"
    write_vtp(path, pos, data)
    poly = read_vtp(path)

    assert poly.GetNumberOfPoints() == n
    pts = vtk_to_numpy(poly.GetPoints().GetData())
    assert pts.dtype == np.float32 and pts.shape == (n, 3)
    np.testing.assert_array_equal(pts[:, :2], pos)
    np.testing.assert_array_equal(pts[:, 2], 0)

    assert poly.GetNumberOfVerts() == n and poly.GetNumberOfCells() == n
    conn = vtk_to_numpy(poly.GetVerts().GetConnectivityArray())
    offs = vtk_to_numpy(poly.GetVerts().GetOffsetsArray())
    np.testing.assert_array_equal(conn, np.arange(n))
    np.testing.assert_array_equal(offs, np.arange(n + 1))

    pd = poly.GetPointData()
    rho = vtk_to_numpy(pd.GetArray("density"))
    assert rho.dtype == np.float32 and rho.shape == (n,)
    np.testing.assert_array_equal(rho, data["density"])

    vel = vtk_to_numpy(pd.GetArray("velocity"))
    assert vel.dtype == np.float32 and vel.shape == (n, 3)
    np.testing.assert_array_equal(vel[:, :2], data["velocity"])
    np.testing.assert_array_equal(vel[:, 2], 0)

    ids = vtk_to_numpy(pd.GetArray("id"))
    assert ids.dtype == np.int32
    np.testing.assert_array_equal(ids, data["id"])

    p64 = vtk_to_numpy(pd.GetArray("pressure64"))
    assert p64.dtype == np.float64
    np.testing.assert_array_equal(p64, data["pressure64"])


def test_vtp_3d_positions_kept(tmp_path):
    pos = np.arange(12, dtype=np.float64).reshape(4, 3)
    write_vtp(tmp_path / "p.vtp", pos, {})
    pts = vtk_to_numpy(read_vtp(tmp_path / "p.vtp").GetPoints().GetData())
    assert pts.dtype == np.float64
    np.testing.assert_array_equal(pts, pos)


def test_vtp_empty(tmp_path):
    pos, data = particles(0)
    write_vtp(tmp_path / "empty.vtp", pos, data)
    poly = read_vtp(tmp_path / "empty.vtp")
    assert poly.GetNumberOfPoints() == 0
    assert poly.GetNumberOfCells() == 0


def test_vtp_rejects_bad_shapes():
    with pytest.raises(ValueError):
        output.vtp_bytes(np.zeros((3, 4), np.float32), {})
    with pytest.raises(ValueError):
        output.vtp_bytes(np.zeros((3, 2), np.float32), {"rho": np.zeros(2)})


def pvd_entries(path):
    root = ET.parse(path).getroot()
    assert root.get("type") == "Collection"
    return [(float(d.get("timestep")), d.get("file")) for d in root.iter("DataSet")]


def test_snapshot_series_and_resume(tmp_path):
    out = tmp_path / "run"
    series = SnapshotSeries(out, "fluid")
    # Added out of order on purpose: the .pvd must list them by step.
    for step, t in [(20, 0.2), (0, 0.0), (10, 0.1)]:
        pos, data = particles(5 + step, seed=step)
        written = series.add(step, t, pos, data)
        assert written == out / f"fluid_{step:07d}.vtp"

    expected = [(0.0, "fluid_0000000.vtp"), (0.1, "fluid_0000010.vtp"), (0.2, "fluid_0000020.vtp")]
    assert pvd_entries(out / "fluid.pvd") == expected
    assert series.files == [out / f for _, f in expected]
    for (_, f), step in zip(expected, [0, 10, 20]):
        assert read_vtp(out / f).GetNumberOfPoints() == 5 + step

    # A resumed run keeps the earlier entries and adds its own.
    resumed = SnapshotSeries(out, "fluid")
    assert resumed.files == series.files
    pos, data = particles(3, seed=30)
    resumed.add(30, 0.3, pos, data)
    entries = pvd_entries(out / "fluid.pvd")
    assert entries == expected + [(0.3, "fluid_0000030.vtp")]
    assert len(resumed.files) == 4
    assert all(p.exists() for p in resumed.files)

    # Re-adding a listed step replaces that entry rather than duplicating it.
    pos, data = particles(7, seed=99)
    resumed.add(10, 0.15, pos, data)
    entries = pvd_entries(out / "fluid.pvd")
    assert [f for _, f in entries].count("fluid_0000010.vtp") == 1
    assert (0.15, "fluid_0000010.vtp") in entries and len(entries) == 4
    assert read_vtp(out / "fluid_0000010.vtp").GetNumberOfPoints() == 7

    # Only the final files are left: no temporary files.
    assert not [p for p in out.iterdir() if ".tmp-" in p.name]


def test_series_in_a_run_folder_takes_only_its_manifests_files(tmp_path):
    """With a RunFolder, the .pvd's entries not in the manifest are dropped (their files left alone),
    each snapshot is listed before it is written, and a .vtp of the run's name that the manifest does
    not list is refused, not replaced."""
    from sphcore import folder

    out = tmp_path / "run"
    with folder.RunFolder(out) as run_folder:
        SnapshotSeries(out, "fluid", folder=run_folder).add(0, 0.0, *particles(4))
    pvd = ET.parse(out / "fluid.pvd")
    ET.SubElement(pvd.getroot().find("Collection"), "DataSet", timestep="-1", file="experiment_2024001.vtp")
    pvd.write(out / "fluid.pvd")
    (out / "experiment_2024001.vtp").write_bytes(b"mine")
    (out / "fluid_0000020.vtp").write_bytes(b"mine too")
    with folder.RunFolder(out) as run_folder:
        series = SnapshotSeries(out, "fluid", folder=run_folder)
        assert series.files == [out / "fluid_0000000.vtp"]
        series.add(10, 0.1, *particles(5, seed=1))
        assert {"fluid.pvd", "fluid_0000000.vtp", "fluid_0000010.vtp"} == run_folder.names
        with pytest.raises(folder.FolderError, match="fluid_0000020.vtp: a file no sphcore run wrote"):
            series.add(20, 0.2, *particles(5, seed=2))
    assert [f for _, f in pvd_entries(out / "fluid.pvd")] == ["fluid_0000000.vtp", "fluid_0000010.vtp"]
    assert (out / "experiment_2024001.vtp").read_bytes() == b"mine"
    assert (out / "fluid_0000020.vtp").read_bytes() == b"mine too"


def test_atomic_write_keeps_old_file_when_replace_fails(tmp_path, monkeypatch):
    path = tmp_path / "state.bin"
    atomic_write_bytes(path, b"old content")
    assert path.read_bytes() == b"old content"

    def broken_replace(src, dst):
        raise OSError("disk on fire")

    monkeypatch.setattr(os, "replace", broken_replace)
    with pytest.raises(OSError, match="disk on fire"):
        atomic_write_bytes(path, b"new content that never lands")
    assert path.read_bytes() == b"old content"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["state.bin"]


def test_atomic_write_keeps_old_file_when_data_is_bad(tmp_path):
    path = tmp_path / "state.bin"
    path.write_bytes(b"old")
    with pytest.raises(TypeError):
        atomic_write_bytes(path, "not bytes")  # f.write raises inside the temp-file block
    assert path.read_bytes() == b"old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["state.bin"]


def test_atomic_savez_roundtrip(tmp_path):
    path = tmp_path / "checkpoint.npz"
    pos = np.random.default_rng(1).random((10, 2), dtype=np.float32)
    atomic_savez(path, position=pos, step=np.int64(42), scene=np.array("dam_break"))
    with np.load(path) as z:
        np.testing.assert_array_equal(z["position"], pos)
        assert z["position"].dtype == np.float32
        assert int(z["step"]) == 42
        assert z["scene"].shape == () and str(z["scene"]) == "dam_break"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["checkpoint.npz"]


def test_atomic_savez_same_bytes_at_another_time(tmp_path, monkeypatch):
    """The same arrays written a year later give the same bytes (no time stamp inside), so two
    runs' files can be compared byte for byte."""
    import time
    arrays = {"position": np.arange(6, dtype=np.float32).reshape(3, 2), "step": np.int64(7)}
    atomic_savez(tmp_path / "a.npz", **arrays)
    later = time.time() + 86400 * 400  # another day, another year
    monkeypatch.setattr(time, "time", lambda: later)
    atomic_savez(tmp_path / "b.npz", **arrays)
    assert (tmp_path / "a.npz").read_bytes() == (tmp_path / "b.npz").read_bytes()
    with np.load(tmp_path / "b.npz", allow_pickle=False) as z:
        assert sorted(z.files) == ["position", "step"]
        np.testing.assert_array_equal(z["position"], arrays["position"])


def test_parallel_snapshot_pieces_read_as_one(tmp_path):
    """A .pvtp naming two .vtp pieces (add_parallel) reads, through VTK's parallel reader, as the pieces' points
    joined, with their arrays; listed in the .pvd; truncate deletes it and its pieces."""
    series = SnapshotSeries(tmp_path, "demo")
    a, b = particles(5, seed=1), particles(7, seed=2)
    for name, (pos, data) in zip(series.piece_names(10, 2), (a, b)):
        write_vtp(tmp_path / name, pos, data)
    series.add_parallel(10, 0.5, 2, *a)
    reader = vtk.vtkXMLPPolyDataReader()
    reader.SetFileName(str(tmp_path / "demo_0000010.pvtp"))
    reader.Update()
    assert reader.GetErrorCode() == 0
    poly = reader.GetOutput()
    points = vtk_to_numpy(poly.GetPoints().GetData())
    assert np.array_equal(points[:, :2], np.concatenate([a[0], b[0]])) and (points[:, 2] == 0).all()
    density = vtk_to_numpy(poly.GetPointData().GetArray("density"))
    assert np.array_equal(density, np.concatenate([a[1]["density"], b[1]["density"]]))
    assert output.read_pvd(tmp_path / "demo.pvd") == [("demo_0000010.pvtp", 0.5)]
    assert SnapshotSeries(tmp_path, "demo").files == [tmp_path / "demo_0000010.pvtp"]
    series.truncate(5)
    assert sorted(os.listdir(tmp_path)) == ["demo.pvd"]
