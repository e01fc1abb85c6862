"""What one submission costs the host, from vkQueueSubmit until it knows the work is done: an empty command buffer,
and a 16 MiB copy within the device, each submitted and waited for 300 times, the fence waited for by
vkWaitForFences (what sphcore.vk_runner.Context.submit did) or polled with vkGetFenceStatus. A rank of
sphcore.parallel makes several small submissions a step. Prints one JSON line (microseconds: median, mean) and
appends it to argv[1] where given. On a GPU: `. benchmarks/gpu_env.sh; python3 benchmarks/submit_latency.py`.
"""
import json
import sys
import time

import numpy as np

from sphcore.vk_runner import Context

REPEATS = 300
ctx = Context()
vk = ctx.vk
a, b = ctx.buffer(16 << 20, "a"), ctx.buffer(16 << 20, "b")
empty = ctx.record().end()
copy = ctx.record()
vk.vkCmdCopyBuffer(copy.command_buffer, a.buffer, b.buffer, 1, [vk.VkBufferCopy(0, 0, 16 << 20)])
copy = copy.end()


def waited(rec):
    vk.vkQueueSubmit(ctx.queue, 1, [vk.VkSubmitInfo(sType=vk.VK_STRUCTURE_TYPE_SUBMIT_INFO, commandBufferCount=1,
                                                    pCommandBuffers=[rec.command_buffer])], ctx.fence)
    vk.vkWaitForFences(ctx.device, 1, [ctx.fence], vk.VK_TRUE, 10**10)
    vk.vkResetFences(ctx.device, 1, [ctx.fence])


def polled(rec):
    vk.vkQueueSubmit(ctx.queue, 1, [vk.VkSubmitInfo(sType=vk.VK_STRUCTURE_TYPE_SUBMIT_INFO, commandBufferCount=1,
                                                    pCommandBuffers=[rec.command_buffer])], ctx.fence)
    while vk.lib.vkGetFenceStatus(ctx.device, ctx.fence) != vk.VK_SUCCESS:
        pass
    vk.vkResetFences(ctx.device, 1, [ctx.fence])


line = {"device": ctx.device_name}
for name, rec in (("empty", empty), ("copy_16mib", copy)):
    for how, submit in (("wait", waited), ("poll", polled)):
        seconds = []
        for _ in range(REPEATS):
            start = time.perf_counter()
            submit(rec)
            seconds.append(time.perf_counter() - start)
        seconds = 1e6 * np.array(seconds[20:])
        line[f"{name}_{how}_us"] = [round(float(np.median(seconds)), 1), round(float(seconds.mean()), 1)]
print(json.dumps(line))
if len(sys.argv) > 1:
    with open(sys.argv[1], "a") as f:
        f.write(json.dumps(line) + "\n")
