"""benchmarks/parallel_gpu.py with each call of a rank's step timed by the host clock: where the exchange's and the
stages' milliseconds go (the backend's submissions, the peers' copies, the pick, the balance). Run under mpiexec as
parallel_gpu.py is, with its arguments (--warmup: the steps before the timing); after its JSON line, rank 0 prints
one line a rank, `CALLS rank {call: ms a timed step}` (calls nest: exchange holds pick, swap_peers; swap_peers holds
pack (run_pack_rows), publish, pull; run_stages: the step's submissions, with the received rows' writes and the
pick; settle: the wait for the step's first submission and the last step's second where the exchange overlaps
the step's end, or in the exchange where the rows go through host memory):

    mpiexec -n 4 python benchmarks/exchange_calls.py --count 33554432 --steps 30 --warmup 100 --out /tmp/calls.json
"""
import functools
import json
import sys
import time
from collections import defaultdict
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from mpi4py import MPI  # noqa: E402

from sphcore import backends, decomposition, parallel, peers, stepper  # noqa: E402
import parallel_gpu  # noqa: E402

SECONDS = defaultdict(float)  # (a call's seconds, summed over the timed steps)
TIMING = {"steps": 0, "warmup": int(sys.argv[sys.argv.index("--warmup") + 1]) if "--warmup" in sys.argv else 3}


def timed(owner, name, key=None):
    """Time each call of owner.name (under `key(args)` where given) once the warm-up steps have run."""
    call = getattr(owner, name)

    @functools.wraps(call)
    def wrapper(*args, **kwargs):
        start = time.perf_counter()
        try:
            return call(*args, **kwargs)
        finally:
            if TIMING["steps"] > TIMING["warmup"]:
                SECONDS[key(args) if key else name] += time.perf_counter() - start
    setattr(owner, name, wrapper)


def stage_key(args):
    """A submission of one exchange stage by its name (run_pick_rows, run_pack_rows), the step's as run_stages."""
    names = [getattr(s, "name", s) for s in args[1]]
    return f"run_{names[0]}" if names in (["pick_rows"], ["pack_rows"]) else "run_stages"


def count_steps(step):
    def counted(rank):
        TIMING["steps"] += 1
        step(rank)
    return counted


parallel.Rank.step = count_steps(parallel.Rank.step)
timed(parallel.Rank, "step")
timed(backends.VulkanBackend, "run_stages", stage_key)
for name in ("read_regions", "read_rows", "write_rows", "settle"):
    timed(backends.VulkanBackend, name)
for name in ("publish", "pull"):
    timed(peers.Peers, name)
for name in ("write_pick", "pick", "exchange", "swap_peers", "swap_shared", "read_gauges"):
    timed(parallel.Rank, name)
timed(stepper.Simulation, "resize", lambda args: "sim.resize")
timed(decomposition, "balance")


def report():
    steps = max(TIMING["steps"] - TIMING["warmup"], 1)
    rows = MPI.COMM_WORLD.gather({k: round(1e3 * v / steps, 3) for k, v in sorted(SECONDS.items())}, root=0)
    if MPI.COMM_WORLD.Get_rank() == 0:
        for r, row in enumerate(rows):
            print("CALLS", r, json.dumps(row), flush=True)


if __name__ == "__main__":
    parallel_gpu.main()
    report()
