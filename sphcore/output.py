"""Crash-safe output: atomic file writes, .npz checkpoints, VTK .vtp particle snapshots and
the ParaView .pvd collection that ties the snapshots of one run into a time series."""
import base64
import io
import os
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

# numpy dtype -> VTK DataArray type name (little-endian, as declared in the file header).
_VTK_TYPES = {
    np.dtype(np.int8): "Int8", np.dtype(np.uint8): "UInt8",
    np.dtype(np.int16): "Int16", np.dtype(np.uint16): "UInt16",
    np.dtype(np.int32): "Int32", np.dtype(np.uint32): "UInt32",
    np.dtype(np.int64): "Int64", np.dtype(np.uint64): "UInt64",
    np.dtype(np.float32): "Float32", np.dtype(np.float64): "Float64",
}


def atomic_write_bytes(path, data: bytes) -> None:
    """Write `data` to `path` so that `path` holds either its old content or all of `data`.

    The bytes go to a temporary file in the same folder (os.replace is only atomic within one
    file system), are flushed to disk, and the temporary file is then renamed over `path`."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    try:
        with open(tmp, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    # Best effort: make the rename itself durable (POSIX only; directories can't be opened on Windows).
    if hasattr(os, "O_DIRECTORY"):
        try:
            fd = os.open(path.parent, os.O_RDONLY | os.O_DIRECTORY)
            try:
                os.fsync(fd)
            finally:
                os.close(fd)
        except OSError:
            pass


def atomic_savez(path, **arrays) -> None:
    """np.savez(path, **arrays) with the same all-or-nothing guarantee as atomic_write_bytes.
    `path` is used as given (np.savez would append '.npz' to a bare name; we don't).

    The same arrays give the same bytes (zipfile dates every member 1980-01-01), so two runs'
    files can be compared with `cmp`; except record arrays with padding, which numpy's writer
    leaves uninitialised: store those as bytes (`a.view(np.uint8)`)."""
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    atomic_write_bytes(path, buf.getvalue())


def atomic_savefig(fig, path, **options) -> None:
    """fig.savefig(path) (PNG) with the same all-or-nothing guarantee as atomic_write_bytes."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", **options)
    atomic_write_bytes(path, buf.getvalue())


def _data_array(parent, name, arr):
    """Append a format="binary" DataArray: base64(UInt64 byte count) followed by base64(raw data),
    the two encoded separately, as VTK's own uncompressed writer does."""
    arr = np.asarray(arr)
    if arr.dtype == np.bool_:
        arr = arr.astype(np.uint8)
    if arr.dtype not in _VTK_TYPES:
        raise TypeError(f"array {name!r}: dtype {arr.dtype} has no VTK equivalent")
    raw = np.ascontiguousarray(arr, dtype=arr.dtype.newbyteorder("<")).tobytes()
    el = ET.SubElement(parent, "DataArray", type=_VTK_TYPES[arr.dtype], Name=name, format="binary")
    if arr.ndim == 2:
        el.set("NumberOfComponents", str(arr.shape[1]))
    header = np.array([len(raw)], dtype="<u8").tobytes()
    el.text = (base64.b64encode(header) + base64.b64encode(raw)).decode("ascii")


def vtp_bytes(position, point_data) -> bytes:
    """VTK XML PolyData: one point and one vertex cell per particle, plus PointData arrays.

    position: (N, 2) or (N, 3); 2D positions get z = 0.  point_data: name -> (N,) or (N, k)
    array; (N, 2) arrays are padded with a zero third component so ParaView treats them as vectors."""
    pos = np.asarray(position)
    if pos.ndim != 2 or pos.shape[1] not in (2, 3):
        raise ValueError(f"position must have shape (N, 2) or (N, 3), got {pos.shape}")
    n = pos.shape[0]

    def pad3(a):
        return np.concatenate([a, np.zeros((a.shape[0], 1), a.dtype)], axis=1) if a.shape[1] == 2 else a

    root = ET.Element("VTKFile", type="PolyData", version="1.0", byte_order="LittleEndian",
                      header_type="UInt64")
    piece = ET.SubElement(ET.SubElement(root, "PolyData"), "Piece", NumberOfPoints=str(n),
                          NumberOfVerts=str(n), NumberOfLines="0", NumberOfStrips="0",
                          NumberOfPolys="0")
    pd = ET.SubElement(piece, "PointData")
    for name, arr in point_data.items():
        arr = np.asarray(arr)
        if arr.ndim not in (1, 2) or arr.shape[0] != n:
            raise ValueError(f"point_data[{name!r}] must have shape ({n},) or ({n}, k), got {arr.shape}")
        _data_array(pd, name, pad3(arr) if arr.ndim == 2 else arr)
    _data_array(ET.SubElement(piece, "Points"), "Points", pad3(pos))
    verts = ET.SubElement(piece, "Verts")  # vertex cell i holds point i
    _data_array(verts, "connectivity", np.arange(n, dtype=np.int64))
    _data_array(verts, "offsets", np.arange(1, n + 1, dtype=np.int64))
    return ET.tostring(root, encoding="utf-8", xml_declaration=True)


def write_vtp(path, position, point_data) -> None:
    """Atomically write vtp_bytes(position, point_data) to `path`."""
    atomic_write_bytes(path, vtp_bytes(position, point_data))


class SnapshotSeries:
    """Numbered .vtp snapshots in `out_dir` plus `{name}.pvd` listing them for ParaView.

    An existing .pvd is loaded on creation, so a resumed run appends to the earlier series."""

    def __init__(self, out_dir, name):
        self.out_dir = Path(out_dir)
        self.name = name
        self.pvd_path = self.out_dir / f"{name}.pvd"
        self._entries = {}  # file name relative to out_dir -> (step, time)
        if self.pvd_path.exists():
            for ds in ET.parse(self.pvd_path).getroot().iter("DataSet"):
                m = re.search(r"_(\d+)\.vtp$", ds.get("file", ""))
                step = int(m.group(1)) if m else -1  # foreign entries sort first
                self._entries[ds.get("file")] = (step, float(ds.get("timestep", "0")))
        self._update_files()

    def _update_files(self):
        self._order = sorted(self._entries, key=lambda f: self._entries[f])
        self.files = [self.out_dir / f for f in self._order]

    def add(self, step: int, time: float, position, point_data) -> Path:
        """Write snapshot `step`, then rewrite the .pvd; re-adding a step replaces its entry."""
        self.out_dir.mkdir(parents=True, exist_ok=True)
        fname = f"{self.name}_{step:07d}.vtp"
        write_vtp(self.out_dir / fname, position, point_data)
        self._entries[fname] = (int(step), float(time))
        self._update_files()
        root = ET.Element("VTKFile", type="Collection", version="1.0")
        coll = ET.SubElement(root, "Collection")
        for f in self._order:
            ET.SubElement(coll, "DataSet", timestep=repr(self._entries[f][1]), group="", part="0", file=f)
        ET.indent(root)
        atomic_write_bytes(self.pvd_path, ET.tostring(root, encoding="utf-8", xml_declaration=True))
        return self.out_dir / fname
