"""What a copy on the device costs the host, submitted and waited for (Context.submit), by its regions: 42 MiB
(about a rank's halo on 4 GPUs at 33.7 M particles) from one buffer to another as 1, 2, 4, 10 and 40 regions, in one
vkCmdCopyBuffer or a command a region; and one region from and to an exported buffer (sphcore.peers' outbox and
inbox). 42 MiB / 10 is not a multiple of 4 bytes, 42 MiB / 40 is (not of 8); "_by_4" and "_by_16": the regions'
bytes rounded down to a multiple of 4 or 16 (a row of a density is 4 bytes, of a position 16). Prints one JSON line
(median microseconds of 50) and appends it to argv[1] where given. On a GPU:
`. benchmarks/gpu_env.sh; python3 benchmarks/copy_regions.py`.
"""
import json
import sys
import time

import numpy as np

from sphcore.vk_runner import Context
from sphcore.vk_runner.context import Recording

SIZE = 42 << 20
REPEATS = 50
ctx = Context()
vk = ctx.vk
a, b = ctx.buffer(SIZE, "a"), ctx.buffer(SIZE, "b")
exported = ctx.exported_buffer(SIZE, "exported")


def median_us(src, dst, parts, a_command_each, grain=1):
    """The median time of one submission of `parts` equal regions (each SIZE // parts bytes, rounded down to a
    multiple of `grain`) from src to dst."""
    size = SIZE // parts // grain * grain
    regions = [(k * size, k * size, size) for k in range(parts)]
    rec = Recording(ctx)
    for group in ([r] for r in regions) if a_command_each else [regions]:
        array = vk.ffi.new("VkBufferCopy[]", len(group))
        np.frombuffer(vk.ffi.buffer(array), np.uint64).reshape(-1, 3)[:] = group
        vk.vkCmdCopyBuffer(rec.command_buffer, src.buffer, dst.buffer, len(group), array)
    rec = rec.end()
    times = []
    for _ in range(REPEATS + 3):
        start = time.perf_counter()
        ctx.submit(rec)
        times.append(time.perf_counter() - start)
    rec.free()
    return 1e6 * float(np.median(times[3:]))


line = {"device": ctx.device_name, "bytes": SIZE}
for parts in (1, 2, 4, 10, 40):
    line[f"{parts}_regions_one_command_us"] = median_us(a, b, parts, False)
    line[f"{parts}_regions_a_command_each_us"] = median_us(a, b, parts, True)
    for grain in (4, 16):
        line[f"{parts}_regions_one_command_by_{grain}_us"] = median_us(a, b, parts, False, grain)
if exported is not None:
    line["exported_to_device_us"] = median_us(exported[0], a, 1, False)
    line["device_to_exported_us"] = median_us(a, exported[0], 1, False)
print(json.dumps(line), flush=True)
if len(sys.argv) > 1:
    with open(sys.argv[1], "a") as f:
        f.write(json.dumps(line) + "\n")
