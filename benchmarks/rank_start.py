"""What a rank's start costs whatever its share (issue 34): every rank of `mpiexec -n N sphcore run` makes the scene's
initial positions, all of them, to cut the slabs (sphcore.parallel.share), and its Simulation makes them again
before it takes its share. Times, in a fresh process (no MPI), the first scene.initial_positions() of
steps_per_second.py's 3D dam break of --count particles, then share() for rank 1 of --ranks, then that rank's
Simulation (numba; its compiled mirrors cached after a first run). Run from the repository root; to compare two
versions side by side, run each checkout's copy in turn:

    python benchmarks/rank_start.py --count 20000000 --ranks 4 --out benchmarks/results/rank_start.json

Prints and appends one JSON line to --out.
"""
import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from steps_per_second import append_line, case_config  # noqa: E402

import sphcore  # noqa: E402
from sphcore import parallel  # noqa: E402


def seconds(call):
    """(the seconds `call()` took, what it returned)."""
    start = time.perf_counter()
    out = call()
    return round(time.perf_counter() - start, 3), out


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--count", type=int, default=20_000_000)
    parser.add_argument("--ranks", type=int, default=4)
    parser.add_argument("--label", default="", help="a name for the checkout measured")
    parser.add_argument("--out", type=Path, help="append the JSON line here")
    args = parser.parse_args()
    scene = sphcore.Scene.from_dict(case_config(args.count, 3, "grid"))
    positions_s, _ = seconds(scene.initial_positions)
    share_s, (_, keep) = seconds(lambda: parallel.share(scene, args.ranks, 1, np.float32))
    simulation_s, sim = seconds(lambda: sphcore.Simulation(scene, id_order=True, keep=keep))
    sim.close()
    append_line({"label": args.label, "sphcore": str(Path(sphcore.__file__).parent), "particles": scene.fluid_count(),
                 "ranks": args.ranks, "held_by_rank_1": int(keep.sum()), "initial_positions_s": positions_s,
                 "share_s": share_s, "simulation_s": simulation_s}, args.out)


if __name__ == "__main__":
    main()
