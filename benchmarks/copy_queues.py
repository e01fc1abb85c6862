"""A Vulkan device with a second queue from a transfer-only family, and copies recorded and submitted by hand: for
benchmarks/host_copies.py and copy_overlap.py (sphcore's Context has one queue)."""
import vulkan as vk


def with_transfer_queue(make, context_of=lambda made: made):
    """make() (a Context, or what builds one: context_of(made) is its Context) with vkCreateDevice asking for one
    more queue, of the first transfer-only family where there is one: (what make returned, (queue, command pool,
    fence) or None)."""
    family, create = [], vk.vkCreateDevice

    def create_with_transfer(physical, info, allocator):
        families = vk.vkGetPhysicalDeviceQueueFamilyProperties(physical)
        family.append(next((i for i, f in enumerate(families) if f.queueFlags & vk.VK_QUEUE_TRANSFER_BIT
                            and not f.queueFlags & (vk.VK_QUEUE_COMPUTE_BIT | vk.VK_QUEUE_GRAPHICS_BIT)), None))
        queues = [info.pQueueCreateInfos[0].queueFamilyIndex] + ([family[0]] if family[0] is not None else [])
        names = [vk.ffi.string(info.ppEnabledExtensionNames[i]).decode() for i in range(info.enabledExtensionCount)]
        return create(physical, vk.VkDeviceCreateInfo(
            sType=vk.VK_STRUCTURE_TYPE_DEVICE_CREATE_INFO, pNext=info.pNext, queueCreateInfoCount=len(queues),
            pQueueCreateInfos=[vk.VkDeviceQueueCreateInfo(
                sType=vk.VK_STRUCTURE_TYPE_DEVICE_QUEUE_CREATE_INFO, queueFamilyIndex=q, queueCount=1,
                pQueuePriorities=[1.0]) for q in queues],
            enabledExtensionCount=len(names), ppEnabledExtensionNames=names, pEnabledFeatures=info.pEnabledFeatures),
            allocator)

    vk.vkCreateDevice = create_with_transfer
    try:
        made = make()
    finally:
        vk.vkCreateDevice = create
    ctx = context_of(made)
    if family[0] is None:
        return made, None
    queue = vk.vkGetDeviceQueue(ctx.device, family[0], 0)
    pool = vk.vkCreateCommandPool(ctx.device, vk.VkCommandPoolCreateInfo(
        sType=vk.VK_STRUCTURE_TYPE_COMMAND_POOL_CREATE_INFO, queueFamilyIndex=family[0]), None)
    return made, (queue, pool, fence(ctx))


def fence(ctx):
    return vk.vkCreateFence(ctx.device, vk.VkFenceCreateInfo(sType=vk.VK_STRUCTURE_TYPE_FENCE_CREATE_INFO), None)


def command_buffer(ctx, pool, copies):
    """A command buffer of `copies`: (source buffer, destination buffer, regions (source offset, destination
    offset, bytes)) each."""
    buffer = vk.vkAllocateCommandBuffers(ctx.device, vk.VkCommandBufferAllocateInfo(
        sType=vk.VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO, commandPool=pool,
        level=vk.VK_COMMAND_BUFFER_LEVEL_PRIMARY, commandBufferCount=1))[0]
    vk.vkBeginCommandBuffer(buffer, vk.VkCommandBufferBeginInfo(sType=vk.VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO))
    for source, destination, regions in copies:
        vk.vkCmdCopyBuffer(buffer, source, destination, len(regions),
                           [vk.VkBufferCopy(srcOffset=a, dstOffset=b, size=n) for a, b, n in regions])
    vk.vkEndCommandBuffer(buffer)
    return buffer


def submit(ctx, runs, wait=None):
    """Submit each (queue, command buffer, fence) of `runs`, in order; wait for the fences of `wait` (index list;
    default all of them), in order, and reset them."""
    for queue, buffer, done in runs:
        vk.vkQueueSubmit(queue, 1, [vk.VkSubmitInfo(sType=vk.VK_STRUCTURE_TYPE_SUBMIT_INFO, commandBufferCount=1,
                                                    pCommandBuffers=[buffer])], done)
    for k in range(len(runs)) if wait is None else wait:
        wait_for(ctx, runs[k][2])


def wait_for(ctx, done):
    """Wait for fence `done`, and reset it."""
    vk.vkWaitForFences(ctx.device, 1, [done], vk.VK_TRUE, 10**10)
    vk.vkResetFences(ctx.device, 1, [done])
