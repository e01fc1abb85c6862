"""How fast each rank's GPU copies to and from host memory when the ranks of one host copy at once (issue 34: the
exchange of sphcore.parallel goes through host memory), under mpiexec, rank r on GPU r (benchmarks/host_copies.sh).

Each rank copies MiB (argv[1], default 84: an inner rank's exchange at 33.7 M particles on 4 GPUs, in the design
before pick_rows) between a device buffer and: its own part of an MPI shared window (as sphcore.parallel.Shared),
a neighbour's part, private memory it first touched, mapped staging memory; then half each way in one command
buffer, and (where the device has a transfer-only queue family) on that queue, and half each way on two queues.
Prints and appends one JSON line (argv[2]) of each rank's (ms, GB/s) per case: the median of 12 after 3.
"""
import mmap, time, sys, json
import numpy as np
from mpi4py import MPI
import vulkan as vk
from sphcore.vk_runner import context as C

comm = MPI.COMM_WORLD; r, size = comm.Get_rank(), comm.Get_size()
N = int(sys.argv[1]) << 20 if len(sys.argv) > 1 else 84 << 20
OUT = sys.argv[2] if len(sys.argv) > 2 else None

# a second queue, from a transfer-only family where there is one (wrap vkCreateDevice)
extra = {}
orig = vk.vkCreateDevice
def create(physical, info, alloc):
    fams = vk.vkGetPhysicalDeviceQueueFamilyProperties(physical)
    extra["families"] = [(int(f.queueFlags), int(f.queueCount)) for f in fams]
    t = next((i for i, f in enumerate(fams) if f.queueFlags & vk.VK_QUEUE_TRANSFER_BIT
              and not f.queueFlags & (vk.VK_QUEUE_COMPUTE_BIT | vk.VK_QUEUE_GRAPHICS_BIT)), None)
    extra["transfer"] = t
    q0 = info.pQueueCreateInfos[0]
    qs = [vk.VkDeviceQueueCreateInfo(sType=vk.VK_STRUCTURE_TYPE_DEVICE_QUEUE_CREATE_INFO,
                                     queueFamilyIndex=q0.queueFamilyIndex, queueCount=1, pQueuePriorities=[1.0])]
    if t is not None:
        qs.append(vk.VkDeviceQueueCreateInfo(sType=vk.VK_STRUCTURE_TYPE_DEVICE_QUEUE_CREATE_INFO,
                                             queueFamilyIndex=t, queueCount=1, pQueuePriorities=[1.0]))
    names = [vk.ffi.string(info.ppEnabledExtensionNames[i]).decode() for i in range(info.enabledExtensionCount)]
    new = vk.VkDeviceCreateInfo(sType=vk.VK_STRUCTURE_TYPE_DEVICE_CREATE_INFO, pNext=info.pNext,
                                queueCreateInfoCount=len(qs), pQueueCreateInfos=qs,
                                enabledExtensionCount=len(names), ppEnabledExtensionNames=names,
                                pEnabledFeatures=info.pEnabledFeatures)
    return orig(physical, new, alloc)
vk.vkCreateDevice = create
ctx = C.Context()
vk.vkCreateDevice = orig
dev = ctx.buffer(2 * N, "dev")

def page_aligned(n):
    m = mmap.mmap(-1, n + 4096)
    a = np.frombuffer(m, np.uint8)
    a = a[-a.ctypes.data % 4096:][:n]
    a[:] = 1  # first touch by this process
    return a, m

# shared window parts, as sphcore.parallel.Shared makes them
info = MPI.Info.Create(); info.Set("alloc_shared_noncontig", "true")
win = MPI.Win.Allocate_shared(N + 4096, 1, info, comm=comm)
parts = [np.frombuffer(win.Shared_query(q)[0], np.uint8, N + 4096) for q in range(size)]
parts = [p[-p.ctypes.data % 4096:][:N] for p in parts]
parts[r][:] = r  # first touch of one's own part
comm.Barrier()
shared = [ctx.host_buffer(p.ctypes.data, p.nbytes) for p in parts]
local, _m = page_aligned(N)
local_buf = ctx.host_buffer(local.ctypes.data, N)
staging = C._Staging(ctx, N)

# transfer queue pieces
tq = None
if extra.get("transfer") is not None:
    tq = vk.vkGetDeviceQueue(ctx.device, extra["transfer"], 0)
    tpool = vk.vkCreateCommandPool(ctx.device, vk.VkCommandPoolCreateInfo(
        sType=vk.VK_STRUCTURE_TYPE_COMMAND_POOL_CREATE_INFO, queueFamilyIndex=extra["transfer"]), None)
    tfence = vk.vkCreateFence(ctx.device, vk.VkFenceCreateInfo(sType=vk.VK_STRUCTURE_TYPE_FENCE_CREATE_INFO), None)

def record(pool, copies):
    cb = vk.vkAllocateCommandBuffers(ctx.device, vk.VkCommandBufferAllocateInfo(
        sType=vk.VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO, commandPool=pool,
        level=vk.VK_COMMAND_BUFFER_LEVEL_PRIMARY, commandBufferCount=1))[0]
    vk.vkBeginCommandBuffer(cb, vk.VkCommandBufferBeginInfo(sType=vk.VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO))
    for src, dst, regions in copies:
        vk.vkCmdCopyBuffer(cb, src, dst, len(regions), [vk.VkBufferCopy(srcOffset=a, dstOffset=b, size=n) for a, b, n in regions])
    vk.vkEndCommandBuffer(cb)
    return cb

def run(queue, fence, cbs):
    vk.vkQueueSubmit(queue, 1, [vk.VkSubmitInfo(sType=vk.VK_STRUCTURE_TYPE_SUBMIT_INFO, commandBufferCount=len(cbs),
                                                pCommandBuffers=cbs)], fence)
    vk.vkWaitForFences(ctx.device, 1, [fence], vk.VK_TRUE, 10**10)
    vk.vkResetFences(ctx.device, 1, [fence])

def chunks(n, k=8):
    s = n // k
    return [(i * s, i * s, s) for i in range(k)]

def timed(f, reps=15):
    out = []
    for _ in range(reps):
        comm.Barrier(); t = time.perf_counter(); f(); out.append(time.perf_counter() - t)
    return float(np.median(out[3:]))

res = {}
nb = (r + 1) % size
cases = {
    "d2h_own_part": [(dev.buffer, shared[r].buffer, chunks(N))],
    "h2d_neighbour_part": [(shared[nb].buffer, dev.buffer, [(a, N + b, n) for a, b, n in chunks(N)])],
    "d2h_local_private": [(dev.buffer, local_buf.buffer, chunks(N))],
    "h2d_local_private": [(local_buf.buffer, dev.buffer, [(a, N + b, n) for a, b, n in chunks(N)])],
    "d2h_staging": [(dev.buffer, staging.buffer, chunks(N))],
    "both_one_cb": [(dev.buffer, shared[r].buffer, chunks(N // 2)),
                    (shared[nb].buffer, dev.buffer, [(a, N + b, n) for a, b, n in chunks(N // 2)])],
}
for name, copies in cases.items():
    cb = record(ctx.command_pool, copies)
    nbytes = sum(n for _, _, regs in copies for _, _, n in regs)
    s = timed(lambda: run(ctx.queue, ctx.fence, [cb]))
    res[name] = (round(s * 1e3, 2), round(nbytes / s / 1e9, 1))
if tq is not None:
    for name in ("d2h_own_part", "h2d_neighbour_part"):
        cb = record(tpool, cases[name])
        s = timed(lambda: run(tq, tfence, [cb]))
        res["transferq_" + name] = (round(s * 1e3, 2), round(N / s / 1e9, 1))
    # d2h on the transfer queue while h2d on the compute queue, N/2 each
    cb1 = record(tpool, cases["both_one_cb"][:1]); cb2 = record(ctx.command_pool, cases["both_one_cb"][1:])
    def both():
        for q, f, cb in ((tq, tfence, cb1), (ctx.queue, ctx.fence, cb2)):
            vk.vkQueueSubmit(q, 1, [vk.VkSubmitInfo(sType=vk.VK_STRUCTURE_TYPE_SUBMIT_INFO, commandBufferCount=1, pCommandBuffers=[cb])], f)
        vk.vkWaitForFences(ctx.device, 2, [tfence, ctx.fence], vk.VK_TRUE, 10**10)
        vk.vkResetFences(ctx.device, 2, [tfence, ctx.fence])
    s = timed(both)
    res["two_queues_both"] = (round(s * 1e3, 2), round(N / s / 1e9, 1))
res["families"] = extra.get("families")
lines = comm.gather((r, ctx.device_name, res), root=0)
if r == 0:
    print(f"{N >> 20} MiB, ms and GB/s a rank, {size} ranks at once")
    for line in lines:
        print(json.dumps(line))
    if OUT:
        with open(OUT, "a") as f:
            f.write(json.dumps({"benchmark": "host_copies", "mib": N >> 20, "ranks": size, "per_rank": lines}) + "\n")
