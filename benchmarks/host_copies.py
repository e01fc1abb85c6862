"""How fast each rank's GPU copies to and from host memory when the ranks of one host copy at once (issue 34: the
exchange of sphcore.parallel goes through host memory), under mpiexec, rank r on GPU r (benchmarks/host_copies.sh).

Each rank copies MiB (argv[1], default 84: an inner rank's exchange at 33.7 M particles on 4 GPUs, in the design
before pick_rows) between a device buffer and: its own part of an MPI shared window (as sphcore.parallel.Shared),
a neighbour's part, private memory it first touched, mapped staging memory; then half each way in one command
buffer; and, where the device has a transfer-only queue family, the first two on that queue, and half each way on
the two queues at once. Prints and appends one JSON line (argv[2]) of each rank's (ms, GB/s) per case: the median of
the last 12 of 15.
"""
import json
import mmap
import sys
import time

import numpy as np
from mpi4py import MPI

from sphcore.vk_runner import context
from copy_queues import command_buffer, submit, with_transfer_queue

comm = MPI.COMM_WORLD
rank, size = comm.Get_rank(), comm.Get_size()
N = (int(sys.argv[1]) if len(sys.argv) > 1 else 84) << 20
OUT = sys.argv[2] if len(sys.argv) > 2 else None

ctx, transfer = with_transfer_queue(context.Context)
device = ctx.buffer(2 * N, "device")

# each rank's part of a shared window, as sphcore.parallel.Shared makes them, first touched by its rank
info = MPI.Info.Create()
info.Set("alloc_shared_noncontig", "true")
window = MPI.Win.Allocate_shared(N + 4096, 1, info, comm=comm)
parts = [np.frombuffer(window.Shared_query(q)[0], np.uint8, N + 4096) for q in range(size)]
parts = [part[-part.ctypes.data % 4096:][:N] for part in parts]
parts[rank][:] = rank
comm.Barrier()
shared = [ctx.host_buffer(part.ctypes.data, N) for part in parts]
private_map = mmap.mmap(-1, N + 4096)
private = np.frombuffer(private_map, np.uint8)
private = private[-private.ctypes.data % 4096:][:N]
private[:] = 1
private_buffer = ctx.host_buffer(private.ctypes.data, N)
staging = context._Staging(ctx, N)


def chunks(n, shift=0, k=8):
    """k regions (source offset, destination offset, bytes) of n bytes, the destination `shift` bytes on."""
    return [(i * (n // k), shift + i * (n // k), n // k) for i in range(k)]


def timed(run, repeats=15):
    seconds = []
    for _ in range(repeats):
        comm.Barrier()
        start = time.perf_counter()
        run()
        seconds.append(time.perf_counter() - start)
    return float(np.median(seconds[3:]))


neighbour = (rank + 1) % size
cases = {
    "d2h_own_part": [(device.buffer, shared[rank].buffer, chunks(N))],
    "h2d_neighbour_part": [(shared[neighbour].buffer, device.buffer, chunks(N, N))],
    "d2h_local_private": [(device.buffer, private_buffer.buffer, chunks(N))],
    "h2d_local_private": [(private_buffer.buffer, device.buffer, chunks(N, N))],
    "d2h_staging": [(device.buffer, staging.buffer, chunks(N))],
    "both_one_cb": [(device.buffer, shared[rank].buffer, chunks(N // 2)),
                    (shared[neighbour].buffer, device.buffer, chunks(N // 2, N))],
}
results = {}
for name, copies in cases.items():
    buffer = command_buffer(ctx, ctx.command_pool, copies)
    seconds = timed(lambda: submit(ctx, [(ctx.queue, buffer, ctx.fence)]))
    results[name] = (round(seconds * 1e3, 2), round(sum(n for *_, regions in copies for *_, n in regions) / seconds / 1e9, 1))
if transfer is not None:
    queue, pool, fence = transfer
    for name in ("d2h_own_part", "h2d_neighbour_part"):
        buffer = command_buffer(ctx, pool, cases[name])
        seconds = timed(lambda: submit(ctx, [(queue, buffer, fence)]))
        results["transferq_" + name] = (round(seconds * 1e3, 2), round(N / seconds / 1e9, 1))
    out, back = (command_buffer(ctx, pool, cases["both_one_cb"][:1]),
                 command_buffer(ctx, ctx.command_pool, cases["both_one_cb"][1:]))
    seconds = timed(lambda: submit(ctx, [(queue, out, fence), (ctx.queue, back, ctx.fence)]))
    results["two_queues_both"] = (round(seconds * 1e3, 2), round(N / seconds / 1e9, 1))
lines = comm.gather((rank, ctx.device_name, results), root=0)
if rank == 0:
    print(f"{N >> 20} MiB, ms and GB/s a rank, {size} ranks at once")
    for line in lines:
        print(json.dumps(line))
    if OUT:
        with open(OUT, "a") as f:
            f.write(json.dumps({"benchmark": "host_copies", "mib": N >> 20, "ranks": size, "per_rank": lines}) + "\n")
