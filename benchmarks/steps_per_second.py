"""Steps per second of the all-pairs 2D SPH step against particle count, one backend per run.

Each case is a square block of N particles (the first N of a ceil(sqrt(N))^2 lattice at the
default spacing), half its side from the side walls and 10 m above the floor, gravity on. After a
warm-up (numba compiles, Vulkan records its command buffer) whole chunks of steps are timed
until at least --min-seconds have passed. Vulkan's step() returns only after the fence of
its last submit, so the timer brackets finished GPU work.

    python benchmarks/steps_per_second.py --backend numba --out benchmarks/results/x.json
    python benchmarks/steps_per_second.py --backend vulkan --counts 20000 \
        --local-size 64,128,256 --steps-per-submit 64,256 --out sweep.json

--local-size and --steps-per-submit take comma lists; every combination is timed.
"""
import argparse
import itertools
import json
import math
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

# seed 1's table: frames/s of its Vulkan SPH on a GTX 1070, by particle count
SEED1_GTX1070_FPS = {5000: 486.8, 10000: 271.8, 20000: 115.95, 30000: 59.15,
                     40000: 39.7, 50000: 35.75, 60000: 28.4}


def ints(text):
    return [int(v) for v in text.split(",") if v]


DROP_M = 10.0  # free fall before the floor: 1.43 s = 14000 steps of dt = 1e-4 s


def make_case(n, spacing=0.01):
    """(scene, positions) for a block of exactly n particles, DROP_M above the floor of a box."""
    from sphcore.scene import Scene
    side = math.ceil(math.sqrt(n))
    block = side * spacing
    x0, y0 = block / 2, DROP_M  # block half its side from the side walls and from the ceiling
    scene = Scene.from_dict({
        "name": f"bench_{n}",
        "domain": {"box_min": [0.0, 0.0], "box_max": [2 * block, y0 + 1.5 * block]},
        "fluid": {"spacing": spacing,
                  "blocks": [{"min": [x0, y0], "max": [x0 + block + spacing / 2, y0 + block + spacing / 2]}]},
        "forces": {"gravity": [0.0, -9.81]},
    })
    x = scene.initial_positions()
    assert len(x) >= n, (len(x), n)
    return scene, x[:n]


def time_case(backend, n, local_size, steps_per_submit, min_steps, min_seconds, device=None):
    from sphcore.backends import empty_state, make_backend, plan
    scene, x = make_case(n)
    state = empty_state(n)
    state["particle_x"][:] = x
    options = {"local_size": local_size}
    if backend == "vulkan":
        options.update(steps_per_submit=steps_per_submit, device=device)
        chunk = max(steps_per_submit, min_steps // steps_per_submit * steps_per_submit)
    else:
        chunk = max(1, min_steps)
    be = make_backend(backend, scene.params(n), state, plan(scene), **options)
    try:
        t0 = time.perf_counter()
        be.step(chunk if backend == "vulkan" else 1)  # numba compiles; vulkan records and runs once
        warmup = time.perf_counter() - t0
        be.read()  # sync
        steps, start = 0, time.perf_counter()
        while True:
            be.step(chunk)
            steps += chunk
            seconds = time.perf_counter() - start
            if seconds >= min_seconds:
                break
        out = be.read()
        device_name = be.ctx.device_name if backend == "vulkan" else cpu_name()
    finally:
        be.close()
    finite = bool(np.isfinite(out["particle_x"]).all() and np.isfinite(out["particle_v"]).all())
    lo, hi = np.array(scene["domain.box_min"]), np.array(scene["domain.box_max"])
    wall_gap = float(min((out["particle_x"] - lo).min(), (hi - out["particle_x"]).min()))
    return device_name, {"n": n, "local_size": local_size,
                         "steps_per_submit": steps_per_submit if backend == "vulkan" else None,
                         "steps": steps, "seconds": seconds, "steps_per_second": steps / seconds,
                         "ms_per_step": 1e3 * seconds / steps, "warmup_seconds": warmup,
                         "finite": finite, "wall_gap_m_at_end": wall_gap, "h_m": scene.h,
                         "box_max_m": [float(v) for v in hi]}


def cpu_name():
    try:
        for line in open("/proc/cpuinfo"):
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def stub_numba_if_missing():
    """sphcore.backends imports the numba mirrors; the Vulkan path never calls them."""
    try:
        import numba  # noqa: F401
        return None
    except ImportError as e:
        import types
        stub = types.ModuleType("numba")
        stub.njit = lambda *a, **k: a[0] if a and callable(a[0]) else (lambda f: f)
        stub.prange = range
        stub.__version__ = f"stub ({e})"
        sys.modules["numba"] = stub
        return str(e)


def versions():
    out = {"python": platform.python_version(), "numpy": np.__version__}
    for name in ("numba", "llvmlite", "vulkan"):
        try:
            out[name] = __import__(name).__version__
        except Exception as e:  # noqa: BLE001 - record why it is missing
            out[name] = f"unavailable ({type(e).__name__})"
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--backend", choices=["numba", "vulkan"], required=True)
    ap.add_argument("--counts", type=ints, default=sorted(SEED1_GTX1070_FPS))
    ap.add_argument("--steps", type=int, default=None,
                    help="steps per timed chunk (default: numba 1, vulkan 256); chunks repeat until --min-seconds")
    ap.add_argument("--min-seconds", type=float, default=1.0)
    ap.add_argument("--local-size", type=ints, default=[128])
    ap.add_argument("--steps-per-submit", type=ints, default=[64])
    ap.add_argument("--device", default=None, help="Vulkan device index or name substring")
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args()
    stubbed = stub_numba_if_missing() if args.backend == "vulkan" else None
    min_steps = args.steps or (256 if args.backend == "vulkan" else 1)
    spps = args.steps_per_submit if args.backend == "vulkan" else [None]

    record = {"benchmark": "steps_per_second", "backend": args.backend, "device": None,
              "host": {"platform": platform.platform(), "machine": platform.machine(),
                       "processor": platform.processor(), "cpu_count": os.cpu_count(),
                       "loadavg_at_start": os.getloadavg()},
              "versions": versions(),
              "env": {k: os.environ.get(k) for k in ("OMP_WAIT_POLICY", "NUMBA_THREADING_LAYER",
                                                     "NUMBA_NUM_THREADS", "VK_DRIVER_FILES")},
              "numba_stubbed": stubbed, "counts": args.counts, "min_seconds": args.min_seconds, "min_steps": min_steps,
              "scene": {"spacing_m": 0.01, "smoothing_ratio": 2.5, "dt_s": 1e-4, "gravity": [0.0, -9.81],
                        "layout": "first N of a ceil(sqrt(N))^2 block; box 2 blocks wide, block 10 m above the floor"},
              "results": [],
              "seed1_gtx1070_vulkan_fps": {str(k): v for k, v in SEED1_GTX1070_FPS.items()},
              "seed1_note": "seed 1 reported frames/s of its Vulkan build on a GTX 1070"}
    print(f"{'N':>7} {'local':>5} {'spp':>4} {'steps':>6} {'seconds':>8} {'steps/s':>10} {'ms/step':>9}"
          f" {'seed1 fps':>9}  device", flush=True)
    for n, ls, spp in itertools.product(args.counts, args.local_size, spps):
        device, row = time_case(args.backend, n, ls, spp, min_steps, args.min_seconds, args.device)
        record["device"] = device
        record["results"].append(row)
        seed = SEED1_GTX1070_FPS.get(n)
        print(f"{n:>7} {ls:>5} {spp or '-':>4} {row['steps']:>6} {row['seconds']:>8.3f} "
              f"{row['steps_per_second']:>10.2f} {row['ms_per_step']:>9.3f} {seed or '':>9}  {device}"
              + ("" if row["finite"] else "  NON-FINITE STATE"), flush=True)
        record["host"]["loadavg_now"] = os.getloadavg()
        if args.out:  # rewrite after every case so a killed run keeps what it measured
            if args.backend == "numba":
                import numba
                record["env"]["numba_threading_layer_used"] = numba.threading_layer()
            args.out.parent.mkdir(parents=True, exist_ok=True)
            args.out.write_text(json.dumps(record, indent=1) + "\n")


if __name__ == "__main__":
    main()
