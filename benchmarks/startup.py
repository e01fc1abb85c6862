"""Time to the first step, cold and warm: the numba mirrors compiled, or loaded from their cache.

Each run is a fresh Python process with SPHCORE_CACHE_DIR set to a folder of this benchmark's own
(NUMBA_CACHE_DIR unset): "cold" starts from an empty folder, "warm" runs again with the folder the
cold run filled (sphcore/numba_cache.py). Two kinds of run, each cold once and then warm
--repeat times:
- api: `sphcore.Simulation(Scene.load(scene))`, one step, then the rest; the seconds from the
  process's launch to the end of the first step ("first_step") and of the last ("total"), and the
  steady cost of a step after the first ("ms_per_later_step", with the final read);
- cli: `python -m sphcore run SCENE --steps N` as a user types it, snapshots and checkpoints
  written; its wall time ("total").

    python benchmarks/startup.py --scene tank_2d --steps 1000 --out benchmarks/results/startup_cpu.json
"""
import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

API = """
import sys, time
import sphcore
scene = sphcore.Scene.load(sys.argv[1])
with sphcore.Simulation(scene) as sim:
    ready = time.time()
    sim.advance(1)
    first = time.time()
    sim.advance(int(sys.argv[2]) - 1)
    sim.read()
print(ready, first, time.time())
"""


def run(kind, scene, steps, cache_dir, out_dir):
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"} | {"SPHCORE_CACHE_DIR": str(cache_dir)}
    if kind == "api":
        command = [sys.executable, "-c", API, scene, str(steps)]
    else:
        command = [sys.executable, "-m", "sphcore", "run", scene, "--steps", str(steps), "--out", str(out_dir),
                   "--overwrite"]
    start = time.time()
    proc = subprocess.run(command, env=env, cwd=ROOT, capture_output=True, text=True)
    end = time.time()
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(command)} failed:\n{proc.stderr}")
    if kind == "cli":
        return {"total": end - start}
    ready, first, last = map(float, proc.stdout.split())
    return {"ready": ready - start, "first_step": first - start, "total": last - start,
            "ms_per_later_step": 1e3 * (last - first) / max(steps - 1, 1)}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", default="tank_2d")
    ap.add_argument("--steps", type=int, default=100)
    ap.add_argument("--repeat", type=int, default=3, help="warm runs of each kind")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "startup_cpu.json")
    args = ap.parse_args()
    import numba

    record = {"benchmark": "startup", "scene": args.scene, "steps": args.steps,
              "host": {"platform": platform.platform(), "cpu_count": os.cpu_count(), "loadavg_at_start": os.getloadavg()},
              "versions": {"python": platform.python_version(), "numba": numba.__version__},
              "env": {k: os.environ.get(k) for k in ("OMP_WAIT_POLICY", "NUMBA_THREADING_LAYER", "NUMBA_NUM_THREADS")},
              "note": __doc__.split("\n\n")[1], "runs": []}
    print(f"{'kind':>4} {'cache':>5} {'ready s':>8} {'first step s':>13} {'total s':>8} {'ms/later step':>13}",
          flush=True)
    with tempfile.TemporaryDirectory() as tmp:
        for kind in ("api", "cli"):
            cache_dir = Path(tmp) / f"cache_{kind}"
            for k in range(1 + args.repeat):
                row = {"kind": kind, "cache": "warm" if k else "cold"} | run(kind, args.scene, args.steps, cache_dir,
                                                                                Path(tmp) / "run")
                record["runs"].append(row)
                print(f"{kind:>4} {row['cache']:>5} {row.get('ready', float('nan')):>8.2f} "
                      f"{row.get('first_step', float('nan')):>13.2f} {row['total']:>8.2f} "
                      f"{row.get('ms_per_later_step', float('nan')):>13.2f}", flush=True)
        record["cache_files"] = len(list((Path(tmp) / "cache_cli" / "numba").iterdir()))
    record["host"]["loadavg_at_end"] = os.getloadavg()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(record, indent=1) + "\n")
    print(f"-> {args.out}")


if __name__ == "__main__":
    main()
