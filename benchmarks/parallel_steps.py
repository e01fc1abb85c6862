"""The decomposed step (sphcore.parallel) against a plain Simulation's, and what its exchange costs, on the numba
backend (or --backend vulkan: on lavapipe, at a coarse --spacing, what the host spends a step):
`mpiexec -n N python benchmarks/parallel_steps.py [--spacing 0.005] [--steps 50] [--backend numba] [--out FILE]`.

A 2D dam break (dam_break_2d at `--spacing`), each rank building its share (parallel.share), warmed up by 5 steps,
then `--steps` steps timed: on every rank the driver's step split as Rank.seconds splits it (the exchange and its
parts, the stages, the dt); then on rank 0 alone a plain Simulation of the same scene, and one in id order (as the
ranks sort). Writes a JSON line (and --out). A few minutes on the CI machine at the defaults.
"""
import argparse
import json
import platform
import time

import numba
from mpi4py import MPI

import sphcore
from sphcore import parallel


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--spacing", type=float, default=0.005)
    parser.add_argument("--steps", type=int, default=50)
    parser.add_argument("--backend", default="numba", choices=("numba", "vulkan"))
    parser.add_argument("--out")
    args = parser.parse_args()
    world = MPI.COMM_WORLD
    base = sphcore.Scene.load("dam_break_2d").config
    scene = sphcore.Scene.from_dict({**base, "fluid": {**base["fluid"], "spacing": args.spacing}})
    cuts, keep = parallel.share(scene, world.Get_size(), world.Get_rank())
    with sphcore.Simulation(scene, args.backend, id_order=True, keep=keep) as sim:
        rank = parallel.Rank(sim, world, cuts)
        for _ in range(5):
            rank.step()
        rank.seconds = dict.fromkeys(parallel.PARTS, 0.0)
        world.Barrier()
        start = time.perf_counter()
        held = 0
        for _ in range(args.steps):
            rank.step()
            held += sim.n
        seconds = time.perf_counter() - start
        first, end = rank.owned_rows()
        rank.close()
    rows = world.gather({"rank": world.Get_rank(), "ms_per_step": 1e3 * seconds / args.steps,
                         "exchange": rank.exchange_kind,
                         **{f"{p}_ms": 1e3 * rank.seconds[p] / args.steps for p in parallel.PARTS},
                         "owned": int(end - first), "held_mean": held / args.steps}, root=0)
    if world.Get_rank() != 0:
        return
    result = {"ranks": world.Get_size(), "backend": args.backend, "particles": scene.particle_count(),
              "spacing": args.spacing,
              "steps": args.steps, "per_rank": rows, "machine": platform.node(),
              "mpi": MPI.Get_library_version().split(",")[0], "numba_threads": numba.config.NUMBA_NUM_THREADS}
    for key, id_order in (("plain_ms_per_step", False), ("plain_id_order_ms_per_step", True)):
        with sphcore.Simulation(scene, args.backend, id_order=id_order) as sim:
            sim.step(5)
            start = time.perf_counter()
            sim.step(args.steps)
            sim.read()
            result[key] = 1e3 * (time.perf_counter() - start) / args.steps
    line = json.dumps(result)
    print(line)
    if args.out:
        with open(args.out, "a") as f:
            f.write(line + "\n")


if __name__ == "__main__":
    main()
