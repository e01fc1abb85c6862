"""The decomposed 3D dam break (sphcore.parallel) on N ranks, one GPU each: ms per step and what the exchange
(from GPU to GPU, through host memory or MPI messages: SPHCORE_MPI_EXCHANGE, docs/parallel.md) takes of it. Run under mpiexec (benchmarks/parallel_gpu.sh runs the cases):

    mpiexec -n 2 python benchmarks/parallel_gpu.py --count 8388608 --out benchmarks/results/parallel_gpu.json
    mpiexec -n 2 python benchmarks/parallel_gpu.py --count 2097152 --per-rank ...   # weak scaling: 2 M a rank

The scene is steps_per_second.py's 3D dam break (Tait, h = 2 dx, fixed dt or --dt's, a sort every step; its
block's lattice: the count rounded up to a cube), cut in slabs along z. Rank r runs on its host's r-th GPU
(parallel.rank_device; --device overrides). After --warmup steps (shader builds, first recordings), --steps steps
are timed; each rank's step is split as Rank.seconds splits it: exchange (the cuts' Allreduce, the halo's and the
migrants' rows read back, the Alltoallv, the new halo written: what crosses the host),
stages (the plan on the device) and dt (the partials read back and their Allreduce; none at a fixed dt).
The step's time is the slowest rank's (they wait for each other in the alltoall). With --plain, rank 0 of a 1-rank
run then times a plain Simulation of the same scene, as a run on one GPU is (the baseline the decomposed runs
are measured against), and one with id_order (the grid's cells in id order, as the ranks sort them). Appends one
JSON line to --out (and prints it).
"""
import argparse
import platform
import sys
import time
from pathlib import Path

from mpi4py import MPI

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import sphcore  # noqa: E402
from sphcore import parallel  # noqa: E402
from steps_per_second import append_line, case_config  # noqa: E402

PARTS = parallel.PARTS
HOST = ("exchange",)  # the part that moves rows between ranks (the next four are its parts; host_staged_*: its
# share, named when it went through host memory alone)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--count", type=int, default=1_000_000, help="particles in all, or a rank's with --per-rank")
    ap.add_argument("--per-rank", action="store_true", help="weak scaling: --count particles a rank")
    ap.add_argument("--shape", type=int, nargs=3, metavar=("NX", "NY", "NZ"),
                    help="the block's lattice in place of a cube (strong scaling: its NX NY NZ particles in all)")
    ap.add_argument("--steps", type=int, default=20)
    ap.add_argument("--warmup", type=int, default=3)
    ap.add_argument("--backend", default="vulkan", choices=("vulkan", "numba"))
    ap.add_argument("--device", help="Vulkan device of every rank (default: the rank's own, rank_device)")
    ap.add_argument("--plain", action="store_true", help="1 rank: also time a plain Simulation of the scene")
    ap.add_argument("--room", type=float, default=2.0, help="the box's length in blocks (1.6 keeps 200 M particles' grid "
                    "under params.MAX_CELLS)")
    ap.add_argument("--profile", action="store_true", help="then --steps more steps with every stage timed (Vulkan: GPU "
                    "timestamps; the exchange's pick_rows too), each rank's stages in the JSON line (profile)")
    ap.add_argument("--dt", help='time.dt: seconds, "auto" or "adaptive" (default: the case\'s fixed 5e-5 s)')
    ap.add_argument("--out", type=Path)
    args = ap.parse_args()
    comm = MPI.COMM_WORLD
    size, rank_number = comm.Get_size(), comm.Get_rank()
    count = args.count * size if args.per_rank else args.count
    if args.shape:
        count = args.shape[0] * args.shape[1] * args.shape[2]
    config = case_config(count, dim=3, search="grid", room=args.room, shape=args.shape)
    if args.dt:
        config["time"]["dt"] = args.dt if args.dt in ("auto", "adaptive") else float(args.dt)
    scene = sphcore.Scene.from_dict(config)
    options = {}
    if args.backend == "vulkan":
        options["device"] = args.device or parallel.rank_device(comm.Split_type(MPI.COMM_TYPE_SHARED).Get_rank())
    start = time.perf_counter()
    cuts, keep = parallel.share(scene, size, rank_number)
    with sphcore.Simulation(scene, args.backend, id_order=True, keep=keep, **options) as sim:
        rank = parallel.Rank(sim, comm, cuts)
        for _ in range(args.warmup):
            rank.step()
        setup = time.perf_counter() - start
        rank.seconds = dict.fromkeys(PARTS, 0.0)
        held = 0
        comm.Barrier()
        start = time.perf_counter()
        for _ in range(args.steps):
            rank.step()
            held += sim.n
        comm.Barrier()
        seconds = time.perf_counter() - start
        if args.profile:
            from sphcore.profile import Profile
            sim.backend.profile = Profile()
            for _ in range(args.steps):
                rank.step()
            sim.backend.profile.steps = args.steps
            stages = {r["stage"]: r["ms_per_step"] for r in sim.backend.profile.rows()}
        rank.close()
        first, end = rank.owned_rows()
        row = {"rank": rank_number, "device": sim.device_name, "owned": int(end - first),
               "held_mean": held / args.steps, "exchange": rank.exchange_kind, **{f"{p}_ms": 1e3 * rank.seconds[p] / args.steps for p in PARTS}}
        if args.profile:
            row["profile_ms"] = stages
        n = sim.fluid_count
    rows = comm.gather(row, root=0)
    if rank_number != 0:
        return
    ms = 1e3 * seconds / args.steps
    slowest = {p: max(r[f"{p}_ms"] for r in rows) for p in PARTS}
    result = {"ranks": size, "scaling": "weak" if args.per_rank else "strong", "particles": n,
              "dt": config["time"]["dt"],
              "particles_per_rank": n / size, "backend": args.backend, "steps": args.steps, "ms_per_step": ms,
              "host_staged_ms": sum(slowest[p] for p in HOST), "host_staged_share": sum(slowest[p] for p in HOST) / ms,
              **{f"{p}_ms_slowest": slowest[p] for p in PARTS}, "setup_seconds": setup, "per_rank": rows,
              "machine": platform.node(), "mpi": MPI.Get_library_version().split(",")[0].strip()}
    if args.plain and size == 1:
        for key, id_order in (("plain_ms_per_step", False), ("plain_id_order_ms_per_step", True)):
            with sphcore.Simulation(scene, args.backend, id_order=id_order, **options) as sim:
                # as steps_per_second.py times it: a chunk of steps first (recorded, run), then whole chunks (30
                # steps after 3 took 26.9-30.3 ms on an H200 from call to call where chunks of 64 took 22.8)
                chunk = getattr(sim.backend, "steps_per_submit", 1)
                sim.step(chunk)
                sim.backend.read_buffer("grid_status")  # (a sync: a read of a few words, not of every particle)
                start, steps = time.perf_counter(), 0
                while steps < args.steps or time.perf_counter() - start < 1.0:
                    sim.step(chunk)
                    sim.backend.read_buffer("grid_status")
                    steps += chunk
                result[key] = 1e3 * (time.perf_counter() - start) / steps
    append_line(result, args.out)


if __name__ == "__main__":
    main()
