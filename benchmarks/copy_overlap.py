"""Whether a copy between a GPU and host memory runs while the GPU steps (issue 34: what hiding a rank's exchange
behind its stages would take). One process on one GPU: a Simulation of argv[1] particles (steps_per_second.py's 3D
dam break), its device made with a second queue from a transfer-only family where there is one; a step's recording
submitted alone, a 34 MiB copy (device to host, host to device) alone, and the two submitted together: the copy on
the transfer queue, or on the step's own queue. Prints one JSON line (medians, ms): `_with_a_step` the time until
both are done, `_done_after` until the copy is. On the GPU: benchmarks/host_copies.sh.
"""
import json
import mmap
import sys
import time

import numpy as np

import sphcore
from copy_queues import command_buffer, fence, submit, wait_for, with_transfer_queue
from steps_per_second import make_case

N = 34 << 20
scene, _ = make_case(int(sys.argv[1]) if len(sys.argv) > 1 else 8_400_000, dim=3, search="grid")
sim, transfer = with_transfer_queue(lambda: sphcore.Simulation(scene, "vulkan"), lambda sim: sim.backend.ctx)
backend, ctx = sim.backend, sim.backend.ctx
device = ctx.buffer(N, "device")
host_map = mmap.mmap(-1, N + 4096)
host = np.frombuffer(host_map, np.uint8)
host = host[-host.ctypes.data % 4096:][:N]
host[:] = 1
host_buffer = ctx.host_buffer(host.ctypes.data, N)
queue, pool, copy_fence = transfer if transfer is not None else (ctx.queue, ctx.command_pool, fence(ctx))
step_fence = fence(ctx)
step = backend._recording(1, backend.stages).command_buffer
sim.step(30)


def median(run, repeats=8):
    seconds = []
    for _ in range(repeats):
        start = time.perf_counter()
        seconds.append(run(start))
    return round(1e3 * float(np.median(seconds[2:])), 3)


def both(copy):
    """The step and the copy submitted together: (seconds until the copy is done, until both are)."""
    start = time.perf_counter()
    submit(ctx, [(ctx.queue, step, step_fence), copy], wait=[1])
    copied = time.perf_counter() - start
    wait_for(ctx, step_fence)
    return copied, time.perf_counter() - start


result = {"device": ctx.device_name, "particles": sim.n, "transfer_queue": transfer is not None, "mib": N >> 20,
          "step_alone_ms": median(lambda s: (submit(ctx, [(ctx.queue, step, step_fence)]), time.perf_counter() - s)[1])}
copies = {"d2h_transfer_queue": (queue, pool, device, host_buffer),
          "h2d_transfer_queue": (queue, pool, host_buffer, device),
          "d2h_compute_queue": (ctx.queue, ctx.command_pool, device, host_buffer)}
for name, (on, commands, source, destination) in copies.items():
    copy = (on, command_buffer(ctx, commands, [(source.buffer, destination.buffer, [(0, 0, N)])]),
            copy_fence if on is queue else fence(ctx))
    result[name + "_alone_ms"] = median(lambda s: (submit(ctx, [copy]), time.perf_counter() - s)[1])
    result[name + "_done_after_ms"] = median(lambda s: both(copy)[0])
    result[name + "_with_a_step_ms"] = median(lambda s: both(copy)[1])
print(json.dumps(result))
