"""Crash-safe output: atomic file writes, .npz checkpoints, VTK .vtp particle snapshots and
the ParaView .pvd collection that ties the snapshots of one run into a time series."""
import base64
import contextlib
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


@contextlib.contextmanager
def atomic_file(path, dir_fd=None, before_rename=None):
    """An open binary file whose content replaces `path` all at once when the block ends without
    an error: written under a temporary name in the same folder (os.replace is only atomic within
    one file system), flushed to disk, then renamed over `path`. On an error (or a signal) the
    temporary file is removed and `path` keeps its old content.

    With `dir_fd` (an open folder, sphcore.folder.RunFolder), `path` is a name in that folder and
    every step goes through the descriptor: the file lands in that folder even where its path has
    come to name another. `before_rename()` (a check that may raise) runs just before the rename."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    opener = None if dir_fd is None else (lambda name, flags: os.open(name, flags, 0o666, dir_fd=dir_fd))
    try:
        with open(tmp, "wb", opener=opener) as f:
            yield f
            f.flush()
            os.fsync(f.fileno())
        if before_rename is not None:
            before_rename()
        if dir_fd is None:
            os.replace(tmp, path)
        else:
            os.replace(tmp, path, src_dir_fd=dir_fd, dst_dir_fd=dir_fd)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp, dir_fd=dir_fd)
        raise
    # Best effort: make the rename itself durable (POSIX only; directories can't be opened on Windows).
    if dir_fd is not None:
        with contextlib.suppress(OSError):
            os.fsync(dir_fd)
    elif hasattr(os, "O_DIRECTORY"):
        try:
            fd = os.open(path.parent, os.O_RDONLY | os.O_DIRECTORY)
            try:
                os.fsync(fd)
            finally:
                os.close(fd)
        except OSError:
            pass


def atomic_write_bytes(path, data: bytes) -> None:
    """Write `data` to `path` so that `path` holds either its old content or all of `data` (atomic_file)."""
    with atomic_file(path) as f:
        f.write(data)


def atomic_savez(path, **arrays) -> None:
    """np.savez(path, **arrays) with the same all-or-nothing guarantee as atomic_write_bytes.
    `path` is used as given (np.savez would append '.npz' to a bare name; we don't).

    The members are streamed into the temporary file (numpy writes an array in chunks of 16 MiB),
    so no second copy of the state is made in memory. The same arrays give the same bytes
    (zipfile dates every member 1980-01-01), so two runs' files can be compared with `cmp`;
    except record arrays with padding, which numpy's writer leaves uninitialised: store those
    as bytes (`a.view(np.uint8)`)."""
    with atomic_file(path) as f:
        np.savez(f, **arrays)


def atomic_savefig(fig, path, **options) -> None:
    """fig.savefig(path) (PNG) with the same all-or-nothing guarantee as atomic_write_bytes."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", **options)
    atomic_write_bytes(path, buf.getvalue())


_CHUNK_ROWS = 3 * 2**15  # rows encoded at a time: a multiple of 3, so every chunk but the last is whole base64 groups


def _vtk_array(arr, name):
    """`arr` as a VTK-typed numpy array (bool as UInt8), or TypeError naming it."""
    arr = np.asarray(arr)
    if arr.dtype == np.bool_:
        arr = arr.view(np.uint8)
    if arr.dtype not in _VTK_TYPES:
        raise TypeError(f"array {name!r}: dtype {arr.dtype} has no VTK equivalent")
    return arr


def _write_data(f, rows, count, components, dtype):
    """A format="binary" DataArray's text: base64(UInt64 byte count) followed by base64(raw data),
    the two encoded separately, as VTK's own uncompressed writer does. `rows(i, j)` gives rows
    i..j; they are encoded _CHUNK_ROWS at a time, so the file is written without a copy of the
    whole array (base64 of consecutive 3-byte multiples concatenates to base64 of the whole)."""
    dtype = np.dtype(dtype).newbyteorder("<")
    f.write(base64.b64encode(np.array([count * components * dtype.itemsize], "<u8").tobytes()))
    for i in range(0, count, _CHUNK_ROWS):
        f.write(base64.b64encode(np.ascontiguousarray(rows(i, min(i + _CHUNK_ROWS, count)), dtype).tobytes()))


def write_vtp_to(f, position, point_data) -> None:
    """Write VTK XML PolyData to the binary file `f`: one point and one vertex cell per particle,
    plus PointData arrays, streamed (no copy of the arrays is made in memory).

    position: (N, 2) or (N, 3); 2D positions get z = 0.  point_data: name -> (N,) or (N, k)
    array; (N, 2) arrays are padded with a zero third component so ParaView treats them as vectors."""
    pos = np.asarray(position)
    if pos.ndim != 2 or pos.shape[1] not in (2, 3):
        raise ValueError(f"position must have shape (N, 2) or (N, 3), got {pos.shape}")
    n = pos.shape[0]

    def padded(a):  # rows of `a`, a zero third component appended to 2-vectors
        if a.ndim == 2 and a.shape[1] == 2:
            return lambda i, j: np.concatenate([a[i:j], np.zeros((j - i, 1), a.dtype)], axis=1)
        return lambda i, j: a[i:j]

    root = ET.Element("VTKFile", type="PolyData", version="1.0", byte_order="LittleEndian",
                      header_type="UInt64")
    piece = ET.SubElement(ET.SubElement(root, "PolyData"), "Piece", NumberOfPoints=str(n),
                          NumberOfVerts=str(n), NumberOfLines="0", NumberOfStrips="0",
                          NumberOfPolys="0")
    arrays = []  # (rows, components, dtype) of each DataArray, in document order

    def data_array(parent, name, arr, rows):
        if not str(name).isprintable():
            raise ValueError(f"point_data name {name!r} is not printable")
        el = ET.SubElement(parent, "DataArray", type=_VTK_TYPES[arr.dtype], Name=name, format="binary")
        components = 3 if arr.ndim == 2 and arr.shape[1] == 2 else (arr.shape[1] if arr.ndim == 2 else 1)
        if arr.ndim == 2:
            el.set("NumberOfComponents", str(components))
        el.text = f"\x01{len(arrays)}\x01"  # replaced by the data when written
        arrays.append((rows, components, arr.dtype))

    pd = ET.SubElement(piece, "PointData")
    for name, arr in point_data.items():
        arr = _vtk_array(arr, name)
        if arr.ndim not in (1, 2) or arr.shape[0] != n:
            raise ValueError(f"point_data[{name!r}] must have shape ({n},) or ({n}, k), got {arr.shape}")
        data_array(pd, name, arr, padded(arr))
    pos = _vtk_array(pos, "Points")
    data_array(ET.SubElement(piece, "Points"), "Points", pos, padded(pos))
    verts = ET.SubElement(piece, "Verts")  # vertex cell i holds point i
    index = np.zeros(0, np.int64)
    data_array(verts, "connectivity", index, lambda i, j: np.arange(i, j, dtype=np.int64))
    data_array(verts, "offsets", index, lambda i, j: np.arange(i + 1, j + 1, dtype=np.int64))
    text = ET.tostring(root, encoding="utf-8", xml_declaration=True).split(b"\x01")
    for k, part in enumerate(text):
        if k % 2 == 0:
            f.write(part)
        else:
            rows, components, dtype = arrays[int(part)]
            _write_data(f, rows, n, components, dtype)


def vtp_bytes(position, point_data) -> bytes:
    """The bytes write_vtp_to(f, position, point_data) writes."""
    f = io.BytesIO()
    write_vtp_to(f, position, point_data)
    return f.getvalue()


def write_vtp(path, position, point_data) -> None:
    """Atomically write a .vtp snapshot to `path`, streamed (write_vtp_to)."""
    with atomic_file(path) as f:
        write_vtp_to(f, position, point_data)


def snapshot_step(name):
    """The step of a snapshot NAME_NNNNNNN.vtp (-1 for any other name)."""
    m = re.search(r"_(\d+)\.vtp$", str(name))
    return int(m.group(1)) if m else -1


def entry_step(name):
    """The step of a series' entry: a snapshot NAME_NNNNNNN.vtp or a parallel one NAME_NNNNNNN.pvtp (-1 else)."""
    name = str(name)
    return snapshot_step(name[:-5] + ".vtp" if name.endswith(".pvtp") else name)


def piece_name(name, step, rank):
    """The file of rank `rank`'s piece of parallel snapshot `step` (NAME_NNNNNNN_pR.vtp)."""
    return f"{name}_{step:07d}_p{rank}.vtp"


def pvtp_bytes(pieces, position, point_data):
    """A ParaView parallel PolyData file (.pvtp) naming the .vtp files `pieces`, whose arrays are those of
    write_vtp_to(f, position, point_data) (their types and components read from these)."""
    root = ET.Element("VTKFile", type="PPolyData", version="1.0", byte_order="LittleEndian", header_type="UInt64")
    poly = ET.SubElement(root, "PPolyData", GhostLevel="0")

    def declare(parent, name, arr):
        arr = _vtk_array(arr, name)
        components = 3 if arr.ndim == 2 and arr.shape[1] == 2 else (arr.shape[1] if arr.ndim == 2 else 1)
        el = ET.SubElement(parent, "PDataArray", type=_VTK_TYPES[arr.dtype], Name=name)
        if arr.ndim == 2:
            el.set("NumberOfComponents", str(components))

    data = ET.SubElement(poly, "PPointData")
    for name, arr in point_data.items():
        declare(data, name, arr)
    declare(ET.SubElement(poly, "PPoints"), "Points", position)
    for piece in pieces:
        ET.SubElement(poly, "Piece", Source=piece)
    ET.indent(root)
    return ET.tostring(root, encoding="utf-8", xml_declaration=True)


def read_pvd(path):
    """[(file name, time)] of the data sets of ParaView series `path`; raises OSError, xml.etree's ParseError
    (a SyntaxError) or ValueError (a time that is no number)."""
    return [(ds.get("file", ""), float(ds.get("timestep", "nan"))) for ds in ET.parse(path).getroot().iter("DataSet")]


def pvd_bytes(entries):
    """A ParaView series (.pvd) of [(file name, time)]."""
    root = ET.Element("VTKFile", type="Collection", version="1.0")
    coll = ET.SubElement(root, "Collection")
    for name, t in entries:
        ET.SubElement(coll, "DataSet", timestep=repr(float(t)), group="", part="0", file=name)
    ET.indent(root)
    return ET.tostring(root, encoding="utf-8", xml_declaration=True)


class SnapshotSeries:
    """Numbered .vtp snapshots in `out_dir` plus `{name}.pvd` listing them for ParaView.

    An existing .pvd is loaded on creation, so a resumed run appends to the earlier series. With
    `folder` (the run's sphcore.folder.RunFolder) every file goes through it, and only what its
    manifest lists is taken from the folder: a .pvd or a .vtp of someone else's is never adopted
    into the series (nor replaced: the run is refused).

    >>> import tempfile, numpy as np, sphcore
    >>> series = sphcore.SnapshotSeries(tempfile.mkdtemp(), "demo")
    >>> x, rho = np.zeros((3, 2), np.float32), np.full(3, 1000.0, np.float32)
    >>> series.add(0, 0.0, x, {"density": rho}).name
    'demo_0000000.vtp'
    >>> _ = series.add(10, 0.01, x, {"density": rho})
    >>> [f.name for f in series.files], series.pvd_path.name  # what ParaView opens: demo.pvd
    (['demo_0000000.vtp', 'demo_0000010.vtp'], 'demo.pvd')
    """

    def __init__(self, out_dir, name, folder=None):
        self.out_dir = Path(out_dir)
        self.name = name
        self.folder = folder
        self.pvd_path = self.out_dir / f"{name}.pvd"
        self._entries = {}  # file name relative to out_dir -> (step, time)
        if self.pvd_path.exists() and (folder is None or self.pvd_path.name in folder.names):
            for name, time in read_pvd(self.pvd_path):
                if folder is not None and name not in folder.names:
                    continue  # not a snapshot of this run's
                self._entries[name] = (entry_step(name), time)  # (foreign entries, step -1, sort first)
        self._update_files()

    def _update_files(self):
        self._order = sorted(self._entries, key=lambda f: self._entries[f])
        self.files = [self.out_dir / f for f in self._order]

    def _open(self, fname):
        """An atomic_file for out_dir/`fname`, through the run's folder where there is one."""
        if self.folder is not None:
            return self.folder.open(fname)
        self.out_dir.mkdir(parents=True, exist_ok=True)
        return atomic_file(self.out_dir / fname)

    def add(self, step: int, time: float, position, point_data) -> Path:
        """Write snapshot `step`, then rewrite the .pvd; re-adding a step replaces its entry."""
        fname = f"{self.name}_{step:07d}.vtp"
        with self._open(fname) as f:
            write_vtp_to(f, position, point_data)
        self._entries[fname] = (int(step), float(time))
        self._update_files()
        self._write_pvd()
        return self.out_dir / fname

    def piece_names(self, step, ranks):
        """The files of the `ranks` pieces of parallel snapshot `step` (piece_name)."""
        return [piece_name(self.name, step, r) for r in range(ranks)]

    def add_parallel(self, step: int, time: float, ranks, position, point_data) -> Path:
        """List parallel snapshot `step`, whose `ranks` pieces (piece_names) are written, in its .pvtp, then
        rewrite the .pvd (sphcore.parallel: each rank writes its piece, rank 0 calls this with its piece's
        arrays, whose types every piece shares)."""
        fname = f"{self.name}_{step:07d}.pvtp"
        with self._open(fname) as f:
            f.write(pvtp_bytes(self.piece_names(step, ranks), position, point_data))
        self._entries[fname] = (int(step), float(time))
        self._update_files()
        self._write_pvd()
        return self.out_dir / fname

    def truncate(self, step: int) -> None:
        """Drop the snapshots after `step` from the .pvd, then delete their files (only files named
        NAME_NNNNNNN.vtp, or NAME_NNNNNNN.pvtp and its pieces NAME_NNNNNNN_pR.vtp, in out_dir, and with a folder
        only those its manifest lists): a run resumed
        from a checkpoint at `step` continues the series from there, and one resumed to fewer steps
        keeps none of the later ones."""
        later = [f for f, (s, _) in self._entries.items() if s > step]
        if not later:
            return
        for f in later:
            del self._entries[f]
        self._update_files()
        self._write_pvd()
        names = set(self.folder.names) if self.folder is not None else {f.name for f in self.out_dir.iterdir()}
        for f in later:
            if not re.fullmatch(rf"{re.escape(self.name)}_\d{{7}}\.p?vtp", f):
                continue
            gone = [f]
            if f.endswith(".pvtp"):  # and a parallel snapshot's pieces
                gone += sorted(g for g in names if re.fullmatch(re.escape(f[:-5]) + r"_p\d+\.vtp", g))
            for g in gone:
                if self.folder is not None:
                    self.folder.remove(g)
                else:
                    (self.out_dir / g).unlink(missing_ok=True)

    def _write_pvd(self):
        with self._open(self.pvd_path.name) as f:
            f.write(pvd_bytes((name, self._entries[name][1]) for name in self._order))
