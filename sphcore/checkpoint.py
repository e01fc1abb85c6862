"""A checkpoint is untrusted input: every member is checked against the scene before it is read.

`read_checked(path, scene, carried)` first reads each member's .npy header from the zip (dtype and
shape) and compares it with what the scene needs, so a header that claims 25e9 floats costs
nothing; then loads the members (allow_pickle=False; a large one stored uncompressed, as np.savez stores
them, mapped from the file, copy on write: _read) and checks their values: the backend is one
of sphcore's, the step within [0, 1e9], the particle ids a permutation, the grid status clear,
every real value finite and every position inside the walls. A failure is a CheckpointError of
one line naming the file and the field. The energy bound is not taken from the file: the
simulation recomputes it from the scene's initial state (Simulation.restore).
"""
import zipfile

import numpy as np

from sphcore.backends import BACKENDS
from sphcore.errors import CheckpointFieldError
from sphcore.plan import BUFFERS, buffer_dtype, buffer_length
from sphcore.solvers import SOLVERS

MAX_STEP = 10**9  # time.steps' range
MAX_TEXT = 2**20  # characters of the scene's JSON, the backend and device names
MAX_EXTRA = 2**28  # bytes of a member beyond the buffers (a solver's log), loaded as it is
MAPPED_BYTES = 2**20  # a member stored uncompressed from this size on is mapped from the file (_read)
CHECKPOINT = "checkpoint.npz"  # its name in the run's folder
# The buffers that carry the state from one step to the next (and the outputs of the last one): the generic
# ones, then each solver's (whichever solver the scene runs, a checkpoint holds them all); every other buffer
# is rewritten by each step before any stage reads it.
CARRIED = tuple(dict.fromkeys((
    "particle_x", "particle_v", "particle_a", "particle_rho", "particle_p", "particle_id", "grid_status",
    "particle_vh", "time_state",  # Verlet's half-step velocity; dt, the last dt and the time (adaptive dt)
    "control",  # DFSPH's step count, unconverged solves and iteration control; the reused lists' builds
    *(name for solver in SOLVERS.values() for name in solver.carried))))


def expected_members(scene, params, carried):
    """member name -> (dtype, shape) a checkpoint of `scene` must hold; a dtype of kind "U" bounds
    a string's length, None its shape."""
    precision = scene["physics.precision"]
    members = {"step": (np.dtype(np.int64), ()), "scene": (np.dtype(f"<U{MAX_TEXT}"), ()),
               "params": (np.dtype(np.uint8), (params.nbytes,)),
               "backend": (np.dtype("<U64"), ()), "device": (np.dtype("<U1024"), ())}
    for name in carried:
        _, c, length = BUFFERS[name]
        k = buffer_length(length, params)
        members[f"buffer_{name}"] = (buffer_dtype(name, precision), (k, c) if c > 1 else (k,))
    return members


def _header(archive, member):
    """(shape, dtype) from the .npy header of `member`, reading nothing else."""
    with archive.open(member) as f:
        shape, _, dtype = _npy_header(f)
    return shape, dtype


def _npy_header(f):
    """(shape, Fortran order, dtype) of the .npy header at file `f`'s position, which it leaves at the data."""
    version = np.lib.format.read_magic(f)
    read = {(1, 0): np.lib.format.read_array_header_1_0, (2, 0): np.lib.format.read_array_header_2_0}.get(version)
    if read is None:
        raise ValueError(f"unknown .npy version {version}")
    return read(f, max_header_size=10000)


def read_scene(path):
    """The scene's JSON text stored in checkpoint `path` (its header checked first)."""
    with zipfile.ZipFile(path) as archive:
        if "scene.npy" not in archive.namelist():
            raise ValueError("no scene: not a checkpoint of this version of sphcore")
        shape, dtype = _header(archive, "scene.npy")
        if dtype.kind != "U" or shape != () or dtype.itemsize > 4 * MAX_TEXT:
            raise ValueError(f"field scene is {dtype}{list(shape)}, expected a string of at most {MAX_TEXT} characters")
        with archive.open("scene.npy") as f:
            return str(np.lib.format.read_array(f, allow_pickle=False))


def read_checked(path, scene, params, carried, optional=("energy_start",)):
    """The arrays of checkpoint `path`, each checked against `scene` (see the module's docstring);
    raises CheckpointFieldError naming the member, or OSError/ValueError/BadZipFile for a file
    that is no zip of .npy members."""
    members = expected_members(scene, params, carried)
    arrays = {}
    with zipfile.ZipFile(path) as archive:
        stored = {name[:-4]: name for name in archive.namelist() if name.endswith(".npy")}
        for field, (dtype, shape) in list(members.items()) + [(f, (np.dtype(np.float64), ())) for f in optional]:
            if field not in stored:
                if field in optional:
                    continue
                raise CheckpointFieldError(field, "missing: not a checkpoint of this version of sphcore")
            got_shape, got_dtype = _header(archive, stored[field])
            if dtype.kind == "U":
                if got_dtype.kind != "U" or got_shape != () or got_dtype.itemsize > dtype.itemsize:
                    raise CheckpointFieldError(field, f"is {got_dtype}{list(got_shape)}, expected a string of at "
                                               f"most {dtype.itemsize // 4} characters")
            elif field == "params" and got_dtype == dtype and tuple(got_shape) != shape:
                raise CheckpointFieldError(field, f"holds {got_shape[0] if got_shape else 0} bytes where this version's "
                                           f"parameter block has {shape[0]}: a checkpoint of another version of sphcore")
            elif got_dtype != dtype or tuple(got_shape) != shape:
                raise CheckpointFieldError(field, f"is {got_dtype}{list(got_shape)}, this scene needs "
                                           f"{dtype}{list(shape)}")
        extras = sorted(set(stored) - set(members) - set(optional))  # e.g. a solver's log: bounded, no objects
        for field in extras:
            got_shape, got_dtype = _header(archive, stored[field])
            if got_dtype.hasobject or int(np.prod(got_shape)) * got_dtype.itemsize > MAX_EXTRA:
                raise CheckpointFieldError(field, f"is {got_dtype}{list(got_shape)}: no checkpoint holds that")
        for field in [*members, *(f for f in [*optional, *extras] if f in stored)]:
            arrays[field] = _read(path, archive, stored[field])
    check_values(arrays, scene, params, carried)
    return arrays


def _read(path, archive, member):
    """Member `member` of the zip `archive` (the file `path`): mapped from the file, copy on write, where it is a
    large array stored uncompressed (np.savez's), so that the ranks of one host resuming from one checkpoint share
    its pages (each then copies its own rows: sphcore.parallel); else read."""
    info = archive.getinfo(member)
    if info.compress_type == zipfile.ZIP_STORED and info.file_size >= MAPPED_BYTES:
        with open(path, "rb") as f:
            f.seek(info.header_offset + 26)  # (the local header's 30 bytes end with its name's and extra's lengths)
            name, extra = np.frombuffer(f.read(4), "<u2")
            start = info.header_offset + 30 + int(name) + int(extra)  # (the member's first byte)
            f.seek(start)
            shape, fortran, dtype = _npy_header(f)
            offset = f.tell()
        end = offset + dtype.itemsize * int(np.prod(shape))
        if not fortran and not dtype.hasobject and end <= start + info.file_size:
            return np.memmap(path, dtype, "c", offset, shape)
    with archive.open(member) as f:
        return np.lib.format.read_array(f, allow_pickle=False)


def check_values(arrays, scene, params, carried):
    """Raise CheckpointFieldError for the first member whose values no run of `scene` can reach."""
    backend = str(arrays["backend"])
    if backend not in BACKENDS:
        raise CheckpointFieldError("backend", f"{backend[:40]!r} names no backend (choose one of {', '.join(BACKENDS)})")
    step = int(arrays["step"])
    if not 0 <= step <= MAX_STEP:
        raise CheckpointFieldError("step", f"{step} is outside [0, {MAX_STEP}]")
    n = int(params[0]["n"])
    if "particle_id" in carried:
        ids = arrays["buffer_particle_id"]
        if (ids >= n).any() or (np.bincount(ids.astype(np.int64), minlength=n) != 1).any():
            raise CheckpointFieldError("buffer_particle_id", f"is not a permutation of 0..{n - 1}")
    if "grid_status" in carried:
        status = arrays["buffer_grid_status"]
        if status[0] or status[2]:
            raise CheckpointFieldError("buffer_grid_status", f"{status.tolist()} records a failed check")
    for name in carried:
        values = arrays[f"buffer_{name}"]
        if values.dtype.kind == "f" and not np.isfinite(values).all():
            raise CheckpointFieldError(f"buffer_{name}", "holds values that are not finite")
    if "particle_x" in carried and scene["domain.boundary"] == "walls":
        x = arrays["buffer_particle_x"][:, :scene.dim]
        lo = np.asarray(scene["domain.box_min"], np.float32)
        hi = np.asarray(scene["domain.box_max"], np.float32)
        outside = ((x < lo) | (x > hi)).any(axis=1)
        if outside.any():
            raise CheckpointFieldError("buffer_particle_x", f"{int(outside.sum())} position(s) outside the box "
                                       f"{lo.tolist()} .. {hi.tolist()}")
