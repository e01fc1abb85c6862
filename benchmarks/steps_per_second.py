"""Steps per second of the SPH step against particle count, one backend per run.

--dim 2 --search all_pairs (seed 1's case): a square block of N particles (the first N of a
ceil(sqrt(N))^2 lattice), half its side from the side walls and 10 m above the floor.
--dim 3 --search grid (seed 2's case, the default): a 3D dam break, the first N of a
ceil(cbrt(N))^3 block of water in the corner of a tank two blocks long, Tait equation of state,
h = 2 dx (about 33 neighbours per particle), every step re-sorting the particles by cell. After a
warm-up (numba compiles, Vulkan records its command buffer) whole chunks of steps are timed
until at least --min-seconds have passed. Vulkan's step() returns only after the fence of
its last submit, so the timer brackets finished GPU work.

    python benchmarks/steps_per_second.py --backend numba --out benchmarks/results/x.json
    python benchmarks/steps_per_second.py --backend vulkan --counts 20000 \
        --local-size 64,128,256 --steps-per-submit 64,256 --out sweep.json

--local-size, --steps-per-submit and --precision (float32,float64: physics.precision, the
float64 build of the shaders and mirrors) take comma lists; every combination is timed.
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
# seed 2's table 6.1: ms per SPH step, single-thread CPU (Core 2 Q6600) / GPU (GTX 560)
SEED2_MS = {4096: (26.0, 2.2), 8192: (70.2, 3.2), 16384: (227.2, 5.9), 32768: (494.1, 10.2), 65536: (943.2, 20.2)}
COUNTS_3D = [4096, 8192, 16384, 32768, 65536, 131072, 262144]


def ints(text):
    return [int(v) for v in text.split(",") if v]


def precisions(text):
    values = [v for v in text.split(",") if v]
    bad = [v for v in values if v not in ("float32", "float64")]
    if bad or not values:
        raise argparse.ArgumentTypeError(f"choose float32, float64 or both, got {text!r}")
    return values


DROP_M = 10.0  # free fall before the floor: 1.43 s = 14000 steps of dt = 1e-4 s


def append_line(result, out):
    """Print `result` as one JSON line and append it to the file `out` (a Path, or None: printed only)."""
    line = json.dumps(result)
    print(line, flush=True)
    if out:
        out.parent.mkdir(parents=True, exist_ok=True)
        with open(out, "a") as f:
            f.write(line + "\n")


def make_case(n, dim=2, search="all_pairs", spacing=0.01, list_skin=0.0, room=2.0, shape=None):
    """(scene, positions) for exactly n particles: see the module docstring. 3D: the box `room` blocks long; `shape`
    (3D): the block's lattice points along each axis in place of a cube's (n their product)."""
    from sphcore.scene import Scene
    scene = Scene.from_dict(case_config(n, dim, search, spacing, list_skin, room, shape))
    x = scene.initial_positions()
    assert len(x) >= n, (len(x), n)
    return scene, x[:n]


def case_config(n, dim=2, search="all_pairs", spacing=0.01, list_skin=0.0, room=2.0, shape=None):
    """The scene of make_case as a dict (Scene.from_dict's)."""
    if dim == 2:
        side = math.ceil(math.sqrt(n))
        block = side * spacing
        x0, y0 = block / 2, DROP_M  # block half its side from the side walls and from the ceiling
        lo, hi = [x0, y0], [x0 + block + spacing / 2, y0 + block + spacing / 2]
        config = {"domain": {"box_min": [0.0, 0.0], "box_max": [2 * block, y0 + 1.5 * block]},
                  "fluid": {"smoothing_ratio": 2.5}}
    else:
        block = [side * spacing for side in shape or [math.ceil(n ** (1 / 3) - 1e-9)] * 3]
        lo, hi = [0.0, 0.0, 0.0], [side + spacing / 2 for side in block]
        config = {"physics": {"equation_of_state": "tait"},
                  "domain": {"box_min": [0.0, 0.0, 0.0],
                             "box_max": [room * block[0] + spacing, 1.5 * block[1], block[2] + spacing]},
                  "fluid": {"stiffness": 900.0, "viscosity": 0.5}, "time": {"dt": 5e-5}}
    config["physics"] = {"model": "graphics", **config.get("physics", {}), "dimension": dim, "neighbour_search": search}
    if list_skin:
        config["physics"]["list_skin"] = list_skin
    config["name"] = f"bench_{dim}d_{search}_{n}"
    config["fluid"] = {**config["fluid"], "spacing": spacing, "blocks": [{"min": lo, "max": hi}]}
    return config


def time_case(backend, n, dim, search, local_size, steps_per_submit, min_steps, min_seconds, device=None,
              precision="float32", profile=False, list_skin=0.0):
    from sphcore.backends import empty_state, make_backend, plan
    from sphcore.sph.dfsph import CONTROL_BUILDS
    scene, x = make_case(n, dim, search, list_skin=list_skin)
    params = scene.params(n)
    spec = scene.spec_for(backend)  # (neighbour lists)
    state = empty_state(params, precision, max_neighbours=spec.MAX_NEIGHBOURS)
    state["particle_x"][:, :dim] = x
    options = {"local_size": local_size, "precision": precision}
    if backend == "vulkan":
        options.update(steps_per_submit=steps_per_submit, device=device)
        chunk = max(steps_per_submit, min_steps // steps_per_submit * steps_per_submit)
    else:
        chunk = max(1, min_steps)
    be = make_backend(backend, params, state, plan(scene), spec, **options)
    try:
        t0 = time.perf_counter()
        be.step(chunk if backend == "vulkan" else 1)  # numba compiles; vulkan records and runs once
        warmup = time.perf_counter() - t0
        builds_before = int(be.read()["control"][CONTROL_BUILDS])  # (and a sync)
        steps, start = 0, time.perf_counter()
        while True:
            be.step(chunk)
            steps += chunk
            seconds = time.perf_counter() - start
            if seconds >= min_seconds:
                break
        out = be.read()
        builds = int(out["control"][CONTROL_BUILDS]) - builds_before
        device_name = be.ctx.device_name if backend == "vulkan" else cpu_name()
        if profile:  # one more chunk, every dispatch timed (Vulkan: GPU timestamps), apart from the timing above
            from sphcore.profile import Profile, work
            be.profile = Profile()
            be.profile.device = device_name
            be.step(chunk)
            stage_profile = json.loads(be.profile.to_json(*work(scene, be.read()["particle_x"][:, :dim])))
            print(be.profile.table(*work(scene, be.read()["particle_x"][:, :dim])), flush=True)
    finally:
        be.close()
    xs = out["particle_x"][:, :dim]
    finite = bool(np.isfinite(xs).all() and np.isfinite(out["particle_v"]).all())
    lo, hi = np.array(scene["domain.box_min"]), np.array(scene["domain.box_max"])
    wall_gap = float(min((xs - lo).min(), (hi - xs).min()))
    return device_name, {"n": n, "dim": dim, "search": search, "list_skin": list_skin,
                         "list_builds_per_step": builds / steps if list_skin else 1.0,
                         "precision": precision, "local_size": local_size,
                         "steps_per_submit": steps_per_submit if backend == "vulkan" else None,
                         "steps": steps, "seconds": seconds, "steps_per_second": steps / seconds,
                         "ms_per_step": 1e3 * seconds / steps, "particle_steps_per_second": n * steps / seconds,
                         "warmup_seconds": warmup, "grid_status": [int(v) for v in out["grid_status"]],
                         "finite": finite, "wall_gap_m_at_end": wall_gap, "h_m": scene.h,
                         "box_max_m": [float(v) for v in hi], "profile": stage_profile if profile else None}


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
    ap.add_argument("--dim", type=int, choices=[2, 3], default=3)
    ap.add_argument("--search", choices=["grid", "all_pairs"], default="grid")
    ap.add_argument("--counts", type=ints, default=None,
                    help="particle counts (default: seed 1's for 2D all-pairs, seed 2's and up to 262,144 for 3D)")
    ap.add_argument("--steps", type=int, default=None,
                    help="steps per timed chunk (default: numba 1, vulkan 256); chunks repeat until --min-seconds")
    ap.add_argument("--min-seconds", type=float, default=1.0)
    ap.add_argument("--local-size", type=ints, default=[128])
    ap.add_argument("--steps-per-submit", type=ints, default=[64])
    ap.add_argument("--list-skin", type=lambda t: [float(v) for v in t.split(",") if v], default=[0.0],
                    help="physics.list_skin values (comma list): the lists reused between builds, 0: a build every step")
    ap.add_argument("--precision", type=precisions, default=["float32"], help="float32, float64 or both (comma list)")
    ap.add_argument("--device", default=None, help="Vulkan device index or name substring")
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--profile", action="store_true",
                    help="after each timing, one more chunk with every stage timed (Vulkan: GPU timestamps), "
                         "printed and saved with the roofline note (sphcore.profile)")
    args = ap.parse_args()
    if args.counts is None:
        args.counts = sorted(SEED1_GTX1070_FPS) if args.dim == 2 else COUNTS_3D
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
              "dim": args.dim, "search": args.search,
              "scene": make_case(args.counts[0], args.dim, args.search)[0].config | {"layout": __doc__.split("\n\n")[1]},
              "results": [],
              "seed1_gtx1070_vulkan_fps": {str(k): v for k, v in SEED1_GTX1070_FPS.items()},
              "seed1_note": "seed 1 reported frames/s of its Vulkan build on a GTX 1070 (2D, all pairs)",
              "seed2_ms_per_step_cpu_gpu": {str(k): v for k, v in SEED2_MS.items()},
              "seed2_note": "seed 2 table 6.1: ms per 3D step, one Core 2 Q6600 thread / GTX 560 (grid)"}
    print(f"{'N':>8} {'skin':>5} {'builds':>6} {'prec':>7} {'local':>5} {'spp':>4} {'steps':>6} {'seconds':>8} {'steps/s':>10} {'ms/step':>9}"
          f" {'particle-steps/s':>16} {'seed':>12}  device", flush=True)
    for n, skin, precision, ls, spp in itertools.product(args.counts, args.list_skin, args.precision, args.local_size,
                                                         spps):
        device, row = time_case(args.backend, n, args.dim, args.search, ls, spp, min_steps, args.min_seconds,
                                args.device, precision, args.profile, skin)
        record["device"] = device
        record["results"].append(row)
        seed = SEED1_GTX1070_FPS.get(n) if args.dim == 2 else SEED2_MS.get(n)
        print(f"{n:>8} {skin:>5g} {row['list_builds_per_step']:>6.3f} {precision:>7} {ls:>5} {spp or '-':>4} {row['steps']:>6} {row['seconds']:>8.3f} "
              f"{row['steps_per_second']:>10.2f} {row['ms_per_step']:>9.3f} {row['particle_steps_per_second']:>16.4g}"
              f" {str(seed or ''):>12}  {device}" + ("" if row["finite"] else "  NON-FINITE STATE"), flush=True)
        record["host"]["loadavg_now"] = os.getloadavg()
        if args.out:  # rewrite after every case so a killed run keeps what it measured
            if args.backend == "numba":
                import numba
                record["env"]["numba_threading_layer_used"] = numba.threading_layer()
            args.out.parent.mkdir(parents=True, exist_ok=True)
            args.out.write_text(json.dumps(record, indent=1) + "\n")


if __name__ == "__main__":
    main()
