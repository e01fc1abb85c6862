"""A whole `sphcore run` on N GPUs of one host, then its resume on N ranks (issue 34): what a user runs, with the
start, the snapshots (a .vtp piece a rank), the checkpoints and final.npz gathered on rank 0's host. The scene is
steps_per_second.py's 3D dam break, its block a lattice of --shape particles (200 M: 625 640 500). Run from the
repository root on the GPU machine (benchmarks/parallel_run_gpu.sh sets up its environment):

    python benchmarks/parallel_run.py --shape 625 640 500 --ranks 4 --steps 10 --more 10 --out results.json

Prints and appends one JSON line to --out: the seconds of the run and of the resume (wall clock, mpiexec to exit),
each one's last line, and the bytes of each file in the run folder.
"""
import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from steps_per_second import append_line, case_config  # noqa: E402


def toml(config):
    """The scene dict of case_config as TOML (tables of numbers and lists; fluid.blocks as inline tables)."""
    def value(v):
        if isinstance(v, str):
            return json.dumps(v)
        if isinstance(v, list):
            return "[" + ", ".join(value(x) for x in v) + "]"
        if isinstance(v, dict):
            return "{ " + ", ".join(f"{k} = {value(x)}" for k, x in v.items()) + " }"
        return repr(v)
    lines = [f"name = {value(config['name'])}"]
    for table, keys in config.items():
        if isinstance(keys, dict):
            lines += [f"[{table}]"] + [f"{k} = {value(v)}" for k, v in keys.items()]
    return "\n".join(lines) + "\n"


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--shape", type=int, nargs=3, required=True, metavar=("NX", "NY", "NZ"))
    ap.add_argument("--ranks", type=int, default=4)
    ap.add_argument("--steps", type=int, default=10, help="steps of the run")
    ap.add_argument("--more", type=int, default=10, help="steps the resume adds")
    ap.add_argument("--room", type=float, default=1.6)
    ap.add_argument("--run-dir", type=Path, default=Path("/tmp/parallel_run"))
    ap.add_argument("--mpiexec", default="/usr/bin/mpiexec --allow-run-as-root --bind-to none "
                    "--mca btl_vader_single_copy_mechanism cma")
    ap.add_argument("--phase", choices=("run", "resume", "both"), default="both")
    ap.add_argument("--out", type=Path)
    args = ap.parse_args()
    n = args.shape[0] * args.shape[1] * args.shape[2]
    config = case_config(n, 3, "grid", room=args.room, shape=args.shape)
    config["time"] = {**config["time"], "steps": args.steps}
    scene_file = args.run_dir.parent / f"{args.run_dir.name}.toml"
    scene_file.parent.mkdir(parents=True, exist_ok=True)
    scene_file.write_text(toml(config))
    # each rank sees its own GPU alone (parallel_gpu.sh says why)
    launch = [*args.mpiexec.split(), "-n", str(args.ranks), "-x", "PYTHONPATH", "-x", "VK_DRIVER_FILES",
              "-x", "PYTHONUNBUFFERED", "-x", "SPHCORE_CACHE_DIR", "bash", "-c",
              'CUDA_VISIBLE_DEVICES=$OMPI_COMM_WORLD_LOCAL_RANK exec "$0" "$@"', sys.executable, "-m", "sphcore",
              "run"]
    result = {"particles": n, "ranks": args.ranks, "shape": args.shape, "steps": args.steps, "more": args.more}
    phases = {"run": [str(scene_file), "--out", str(args.run_dir), "--overwrite", "--backend", "vulkan"],
              "resume": ["--resume", str(args.run_dir), "--steps", str(args.steps + args.more)]}
    for phase, arguments in phases.items():
        if args.phase not in (phase, "both"):
            continue
        start = time.perf_counter()
        done = subprocess.run(launch + arguments, capture_output=True, text=True)
        result[f"{phase}_seconds"] = time.perf_counter() - start
        result[f"{phase}_rc"] = done.returncode
        result[f"{phase}_last_line"] = (done.stdout.strip().splitlines() or [""])[-1]
        print(done.stdout[-3000:], done.stderr[-3000:], flush=True)
        if done.returncode:
            break
    result["files"] = {f.name: f.stat().st_size for f in sorted(args.run_dir.iterdir())} if args.run_dir.exists() else {}
    result["host_memory_gib"] = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**30
    append_line(result, args.out)


if __name__ == "__main__":
    main()
