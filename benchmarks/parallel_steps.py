"""The decomposed step (sphcore.parallel) against a plain Simulation's, and what its exchange costs, on the numba
backend: `mpiexec -n N python benchmarks/parallel_steps.py [--spacing 0.005] [--steps 50] [--out FILE]`.

A 2D dam break (dam_break_2d at `--spacing`), warmed up by 5 steps, then `--steps` steps timed: on every rank the
driver's step split into the alltoall (pickled particles), Simulation.load and the rest (the plan's stages, the cuts,
the dt's Allreduce); then on rank 0 alone a plain Simulation of the same scene. Writes a JSON line (and --out).
A few minutes on the CI machine at the defaults.
"""
import argparse
import json
import platform
import time

import numba
from mpi4py import MPI

import sphcore
from sphcore import parallel


class Timed:
    """A communicator whose alltoall is timed (everything else passes through)."""

    def __init__(self, comm):
        self.comm, self.seconds = comm, 0.0

    def __getattr__(self, name):
        return getattr(self.comm, name)

    def alltoall(self, sends):
        start = time.perf_counter()
        received = self.comm.alltoall(sends)
        self.seconds += time.perf_counter() - start
        return received


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--spacing", type=float, default=0.005)
    parser.add_argument("--steps", type=int, default=50)
    parser.add_argument("--out")
    args = parser.parse_args()
    world = MPI.COMM_WORLD
    base = sphcore.Scene.load("dam_break_2d").config
    scene = sphcore.Scene.from_dict({**base, "fluid": {**base["fluid"], "spacing": args.spacing}})
    comm = Timed(world)
    with sphcore.Simulation(scene) as sim:
        rank = parallel.Rank(sim, comm)
        for _ in range(5):
            rank.step()
        load_seconds = [0.0]
        load = sim.load

        def timed_load(particles):
            start = time.perf_counter()
            load(particles)
            load_seconds[0] += time.perf_counter() - start

        sim.load = timed_load
        comm.seconds = 0.0
        world.Barrier()
        start = time.perf_counter()
        held = 0
        for _ in range(args.steps):
            rank.step()
            held += sim.n
        seconds = time.perf_counter() - start
        owned = len(rank.owned["particle_id"])
    rows = world.gather({"rank": world.Get_rank(), "ms_per_step": 1e3 * seconds / args.steps,
                         "alltoall_ms": 1e3 * comm.seconds / args.steps, "load_ms": 1e3 * load_seconds[0] / args.steps,
                         "owned": owned, "held_mean": held / args.steps}, root=0)
    if world.Get_rank() != 0:
        return
    with sphcore.Simulation(scene) as sim:
        sim.step(5)
        start = time.perf_counter()
        sim.step(args.steps)
        sim.read()
        plain = 1e3 * (time.perf_counter() - start) / args.steps
    result = {"ranks": world.Get_size(), "particles": sim.n, "spacing": args.spacing, "steps": args.steps,
              "plain_ms_per_step": plain, "per_rank": rows, "machine": platform.node(),
              "mpi": MPI.Get_library_version().split(",")[0],
              "numba_threads": numba.config.NUMBA_NUM_THREADS}
    line = json.dumps(result)
    print(line)
    if args.out:
        with open(args.out, "a") as f:
            f.write(line + "\n")


if __name__ == "__main__":
    main()
