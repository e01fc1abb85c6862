"""How much host memory a run needs at its peak, estimated before anything is allocated, and how
much this process may still use.

The estimate follows what a run holds at once (sphcore.runner.run), from the buffers of
sphcore.backends.BUFFERS at the scene's precision:

- start: the state Simulation builds (`empty_state`) and the backend's copy of it (numba; Vulkan
  writes it to the device), plus the float64 lattice the initial positions are made from;
- a checked read mid-run (the peak): the backend's buffers, their copy that `read()` returns, the
  previous read's carried buffers (kept to replay a failed check from), the particle-order copy
  of the particle buffers and its argsort, and the float64 temporaries of the energy check;
- writing: snapshots (.vtp, base64) and checkpoints (.npz) are streamed to their files in chunks
  (sphcore.output), a bounded few tens of MiB whatever the particle count;
- compiling the kernels (numba's LLVM, or the Vulkan driver's).

Vulkan's device buffers are host memory only where the device is the CPU (lavapipe). The
available memory is the least of MemAvailable, the cgroup's limit less its usage (v1 or v2) and
RLIMIT_AS less the address space in use; SPHCORE_MEMORY_LIMIT (bytes) caps it too (for tests).
"""
import math
import os
import resource
from pathlib import Path

from sphcore.checkpoint import CARRIED
from sphcore.errors import MemoryLimitError
from sphcore.plan import BUFFERS, buffer_dtype, buffer_length

MiB = 2**20
GiB = 2**30
WRITE_CHUNKS = 48 * MiB  # numpy's .npy writer: 16 MiB chunks and their bytes; the .vtp writer's chunks
COMPILE = 320 * MiB  # numba compiling the mirrors (LLVM), or the Vulkan driver its pipelines (measured: ~200 MiB)
ADDRESS_SPACE = 1 * GiB  # address space reserved beyond resident memory (thread stacks, malloc arenas, LLVM)


def particle_count(scene):
    """The particles `scene` starts with, counted without making them."""
    return scene.particle_count()


def buffer_bytes(params, precision, max_neighbours=0, gradients=False):
    """name -> bytes of every buffer of sphcore.backends.BUFFERS for the parameter block `params` (and
    `max_neighbours` list slots a particle; `gradients`: with DFSPH's gradient of each, spec.GRADIENTS)."""
    return {name: buffer_length(length, params, max_neighbours, gradients) * c * buffer_dtype(name, precision).itemsize
            for name, (_, c, length) in BUFFERS.items()}


def estimate(scene, backend="numba", device_in_host=None, n=None):
    """(peak bytes, {term: bytes}) of a run of `scene` on `backend` at its precision. Vulkan's
    device buffers count where `device_in_host` (default: not counted, as on a GPU). `n`
    overrides the particle count (for what-would-fit figures)."""
    n = particle_count(scene) if n is None else n
    precision = scene["physics.precision"]
    spec = scene.spec_for(backend)
    sizes = buffer_bytes(scene.params(n), precision, spec.MAX_NEIGHBOURS, spec.GRADIENTS)
    state = sum(sizes.values())
    carried = sum(sizes[name] for name in CARRIED if name in sizes)
    ordered = sum(size for name, size in sizes.items()
                  if BUFFERS[name][2] == "particles" and name.startswith("particle_"))
    dim = scene.dim
    device = state if backend == "numba" or device_in_host else 0
    staging = 0 if backend == "numba" else max(sizes.values())  # one buffer at a time through host-visible memory
    start = state + device + staging + 3 * n * dim * 8  # empty_state, the backend's buffers, the float64 lattice
    terms = {
        "buffers": device,
        "read copy": state,
        "previous carried": carried,
        "particle order": ordered + 8 * n,
        "energy check": n * (3 * dim + 6) * 8,
        "staging": staging,
        "writing": WRITE_CHUNKS,
    }
    run_peak = sum(terms.values())
    if start > run_peak:
        terms = {"buffers": device, "start state": state, "staging": staging, "lattice": 3 * n * dim * 8}
    terms["compiling"] = COMPILE
    return sum(terms.values()), terms


def _read_int(path):
    try:
        text = Path(path).read_text().strip()
    except OSError:
        return None
    return None if text in ("", "max") else int(text)


def _cgroup():
    """(limit, usage) of this process's memory cgroup (v2, else v1), usage less its inactive file cache; None if unlimited."""
    candidates = []
    try:
        for line in Path("/proc/self/cgroup").read_text().splitlines():
            _, controllers, where = line.split(":", 2)
            if controllers == "":
                candidates.append((Path("/sys/fs/cgroup") / where.lstrip("/"), "memory.max", "memory.current",
                                   "inactive_file"))
            elif "memory" in controllers.split(","):
                candidates.append((Path("/sys/fs/cgroup/memory") / where.lstrip("/"), "memory.limit_in_bytes",
                                   "memory.usage_in_bytes", "total_inactive_file"))
    except OSError:
        pass
    candidates += [(Path("/sys/fs/cgroup"), "memory.max", "memory.current", "inactive_file"),
                   (Path("/sys/fs/cgroup/memory"), "memory.limit_in_bytes", "memory.usage_in_bytes",
                    "total_inactive_file")]
    for folder, limit_file, usage_file, inactive in candidates:
        limit, usage = _read_int(folder / limit_file), _read_int(folder / usage_file)
        if limit is None or usage is None:
            continue
        if limit >= 2**60:  # "unlimited" in cgroup v1
            return None
        try:
            stat = dict(line.split() for line in (folder / "memory.stat").read_text().splitlines())
            usage -= int(stat.get(inactive, 0))
        except (OSError, ValueError):
            pass
        return limit, max(usage, 0)
    return None


def _status_kib(field, path="/proc/self/status"):
    try:
        for line in Path(path).read_text().splitlines():
            if line.startswith(field + ":"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def available():
    """[(bytes, where the figure comes from, whether it limits address space)] of the limits that apply."""
    limits = []
    free = _status_kib("MemAvailable", "/proc/meminfo")
    if free is not None:
        limits.append((free, "MemAvailable", False))
    group = _cgroup()
    if group is not None:
        limits.append((max(group[0] - group[1], 0), f"the cgroup's limit of {group[0] / GiB:.1f} GiB less its use", False))
    soft = resource.getrlimit(resource.RLIMIT_AS)[0]
    if soft != resource.RLIM_INFINITY:
        used = _status_kib("VmSize") or 0
        limits.append((max(soft - used, 0), f"RLIMIT_AS of {soft / GiB:.2f} GiB less the {used / GiB:.2f} GiB in use",
                       True))
    forced = os.environ.get("SPHCORE_MEMORY_LIMIT")
    if forced:
        limits.append((int(float(forced)), "SPHCORE_MEMORY_LIMIT", False))
    return limits


def shortfall(scene, backend="numba", device_in_host=None, n=None):
    """None if a run of `scene` (of n particles: a rank's share) fits the memory available, else (needed,
    available, where) of the first limit it exceeds."""
    needed, _ = estimate(scene, backend, device_in_host, n)
    for free, where, virtual in available():
        if needed + (ADDRESS_SPACE if virtual else 0) > free:
            return needed + (ADDRESS_SPACE if virtual else 0), free, where
    return None


def fits(scene, backend="numba", device_in_host=None):
    return shortfall(scene, backend, device_in_host) is None


def check(scene, backend="numba", device_in_host=None, n=None):
    """Raise MemoryLimitError (one line: both figures and what would fit) if a run of `scene` (of n particles:
    a rank's share) on `backend` would not fit in the memory available."""
    short = shortfall(scene, backend, device_in_host, n)
    if short is None:
        return
    needed, free, where = short
    n = particle_count(scene) if n is None else n
    fixed = estimate(scene, backend, device_in_host, n=0)[0]
    per_particle = (estimate(scene, backend, device_in_host, n)[0] - fixed) / max(n, 1)
    room = free - fixed - (needed - estimate(scene, backend, device_in_host, n)[0])
    fit = int(room / per_particle) if room > 0 else 0
    on = f"{backend}, {scene['physics.precision']}" + (", device memory in host memory" if device_in_host else "")
    if fit > 0:
        spacing = scene["fluid.spacing"] * (n / fit) ** (1.0 / scene.dim)
        step = 10.0 ** (math.floor(math.log10(spacing)) - 1)  # rounded up to two significant digits
        spacing = round(math.ceil(spacing / step) * step, 12)
        what = f"about {fit:,} particles would fit (fluid.spacing = {spacing:g} m or more)"
    else:
        what = ("not even the grid and the kernels fit: raise the limit (ulimit -v)" if "RLIMIT_AS" in where
                else "not even the grid and the kernels fit: free memory, or run on a larger machine")
    raise MemoryLimitError(f"not enough memory: {n:,} particles ({on}) need about {needed / GiB:.2f} GiB at the "
                           f"peak, {free / GiB:.2f} GiB is available ({where}); {what}")
