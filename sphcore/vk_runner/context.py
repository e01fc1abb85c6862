"""Vulkan instance, device, buffers, compute pipelines and command buffers.

Pitfalls of the `vulkan` package handled here: VK_WHOLE_SIZE is -1 there, so the full
64-bit value is passed; pData/pValues take cdata from ffi.from_buffer; create functions
return cdata arrays ([0]); a mapped pointer is copied out before vkUnmapMemory.
"""
import math
import os
import sys
import time

import numpy as np

from sphcore.errors import VulkanError

WHOLE_SIZE = 0xFFFFFFFFFFFFFFFF
FENCE_TIMEOUT_NS = 3600 * 10**9
VALIDATION_LAYER = "VK_LAYER_KHRONOS_validation"
CONDITIONAL_RENDERING = "VK_EXT_conditional_rendering"
HOST_MEMORY = "VK_EXT_external_memory_host"
MEMORY_FD = "VK_KHR_external_memory_fd"
SPIN_SECONDS = 0.01  # a GPU's fence polled this long before the host waits for it (submit: a wait returned 26-29 us
# later than polling for a copy on an H200, benchmarks/submit_latency.py; a step's submission on a rank of 4 H200s
# takes 2-4 ms; not on a CPU device, whose threads the polling slows)
STAGING_KEPT = 1 << 20  # bytes of the staging buffer a Context keeps for copies, at least
STAGING_MOST = 1 << 28  # ... and at most: a copy past that allocates its own


# One VkInstance per process and validation setting, kept until exit: the NVIDIA driver was
# seen to refuse (VK_ERROR_INCOMPATIBLE_DRIVER) the 31st instance created in one process even
# after the previous 30 had been destroyed. Contexts share it and create their own device.
_INSTANCES = {}
_CALLBACKS = []  # the debug callbacks must outlive the instance


def load_vulkan():
    """The `vulkan` module, or a VulkanError that says how to install what is missing."""
    try:
        import vulkan
    except ImportError:
        raise VulkanError("the Python package 'vulkan' is not installed: pip install vulkan "
                          "(or pip install -e '.[vulkan]'), or run with --backend numba") from None
    except OSError as e:  # the package is there, the loader library libvulkan.so.1 is not
        raise VulkanError(f"no Vulkan loader (libvulkan.so.1) could be loaded ({e}): "
                          "apt-get install libvulkan1 mesa-vulkan-drivers, or run with --backend numba") from None
    return vulkan


def _text(value):
    if isinstance(value, str):
        return value
    return load_vulkan().ffi.string(value).decode()


DEVICE_TYPE_RANK = ("DISCRETE_GPU", "INTEGRATED_GPU", "VIRTUAL_GPU", "CPU", "OTHER")


class Buffer:
    """A storage buffer in device-local memory (`uniform`: a uniform buffer); host-mapped where that
    memory is host-visible, which a uniform buffer and a `mapped` one are where the device has such memory (then
    the host writes and reads it with no submission, through `bytes`, a view of it mapped while it lives: a map and
    an unmap an access cost about 20 us of Python, several times a step)."""

    def __init__(self, ctx, nbytes, name, uniform=False, mapped=False):
        vk = ctx.vk
        self.ctx, self.nbytes, self.name = ctx, max(int(nbytes), 4), name
        usage = (vk.VK_BUFFER_USAGE_STORAGE_BUFFER_BIT | vk.VK_BUFFER_USAGE_TRANSFER_SRC_BIT
                 | vk.VK_BUFFER_USAGE_TRANSFER_DST_BIT | vk.VK_BUFFER_USAGE_INDIRECT_BUFFER_BIT)
        if uniform:
            usage = vk.VK_BUFFER_USAGE_UNIFORM_BUFFER_BIT | vk.VK_BUFFER_USAGE_TRANSFER_DST_BIT
        if ctx.conditional_rendering:
            usage |= vk.VK_BUFFER_USAGE_CONDITIONAL_RENDERING_BIT_EXT
        local, host = vk.VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT, (vk.VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT
                                                               | vk.VK_MEMORY_PROPERTY_HOST_COHERENT_BIT)
        self.buffer, self.memory, self.host_visible = ctx._allocate(self.nbytes, usage, local, name,
                                                                    local | host if uniform or mapped else 0)
        self.bytes = np.frombuffer(ctx._map(self.memory, self.nbytes), np.uint8, self.nbytes) \
            if self.host_visible else None

    @classmethod
    def bound(cls, ctx, nbytes, name, buffer, memory):
        """A Buffer over a VkBuffer and the memory bound to it, made elsewhere (Context.host_buffer's,
        exported_buffer's): copied into and out of, not mapped."""
        made = cls.__new__(cls)
        made.ctx, made.nbytes, made.name, made.buffer, made.memory, made.host_visible, made.bytes = (
            ctx, nbytes, name, buffer, memory, False, None)
        return made

    def write(self, array, offset=0, settle=True):
        """Write `array`'s bytes into the buffer from byte `offset` on: after the submission left running
        (Context.submit), or with `settle` False into a host-visible buffer now."""
        data = np.ascontiguousarray(array)
        if offset + data.nbytes > self.nbytes:
            raise ValueError(f"{self.name}: {data.nbytes} bytes at {offset} do not fit in {self.nbytes}")
        if data.nbytes == 0:
            return
        if settle or not self.host_visible:
            self.ctx.settle()
        if self.host_visible:
            self.bytes[offset:offset + data.nbytes] = data.reshape(-1).view(np.uint8)
        else:
            staging = self.ctx._staging(data.nbytes)
            staging.bytes[:data.nbytes] = data.reshape(-1).view(np.uint8)
            self.ctx._copy(staging.buffer, self.buffer, [(0, offset, data.nbytes)])
            self.ctx._release(staging)

    def read(self, dtype, shape, offset=0, settle=True):
        """The buffer's bytes from byte `offset` on, as an array of `dtype` and `shape`: after the submission left
        running (Context.submit), or with `settle` False from a host-visible buffer as they are now."""
        nbytes = int(np.prod(shape)) * np.dtype(dtype).itemsize
        if nbytes == 0:
            return np.zeros(shape, dtype)
        if settle or not self.host_visible:
            self.ctx.settle()
        if self.host_visible:
            return self.bytes[offset:offset + nbytes].copy().view(dtype).reshape(shape)
        staging = self.ctx._staging(nbytes)
        self.ctx._copy(self.buffer, staging.buffer, [(offset, 0, nbytes)])
        out = staging.bytes[:nbytes].copy().view(dtype).reshape(shape)
        self.ctx._release(staging)
        return out

    def copy_within(self, regions):
        """Copy (source byte offset, destination byte offset, byte count) `regions` of the buffer within it,
        on the device (regions must not overlap)."""
        if regions:
            self.ctx._copy(self.buffer, self.buffer, regions)

    def free(self):
        if self.buffer is not None:
            vk = self.ctx.vk
            self.ctx.settle()
            if self.bytes is not None:
                self.bytes = None  # (the view dies before its memory is unmapped)
                vk.vkUnmapMemory(self.ctx.device, self.memory)
            vk.vkDestroyBuffer(self.ctx.device, self.buffer, None)
            vk.vkFreeMemory(self.ctx.device, self.memory, None)
            self.buffer = self.memory = None


class _Staging(Buffer):
    """Host-visible memory for copies, mapped while it lives: `bytes` views it (uint8)."""

    def __init__(self, ctx, nbytes):
        vk = ctx.vk
        self.ctx, self.nbytes, self.name = ctx, nbytes, "staging"
        usage = vk.VK_BUFFER_USAGE_TRANSFER_SRC_BIT | vk.VK_BUFFER_USAGE_TRANSFER_DST_BIT
        flags = vk.VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | vk.VK_MEMORY_PROPERTY_HOST_COHERENT_BIT
        # cached where the device has such memory: the host reads it back (uncached, write-combined memory reads
        # at a fraction of the speed)
        self.buffer, self.memory, self.host_visible = ctx._allocate(nbytes, usage, flags, "staging",
                                                                    flags | vk.VK_MEMORY_PROPERTY_HOST_CACHED_BIT)
        self.bytes = np.frombuffer(ctx._map(self.memory, nbytes), np.uint8, nbytes)


class Pipeline:
    """A compute pipeline over storage buffers at the binding numbers `bindings` (a count n: bindings 0 .. n-1;
    else the numbers, which may be sparse: a stage's own buffers, plan.STAGES), a uniform buffer at
    `uniform_binding` if given, and one push-constant range."""

    def __init__(self, ctx, spirv, bindings, push_size, local_size, spec_values=(), uniform_binding=None):
        vk = ctx.vk
        self.ctx, self.local_size, self.push_size = ctx, local_size, push_size
        self.spec_values, self.uniform_binding = list(spec_values), uniform_binding
        self.numbers = list(range(bindings)) if isinstance(bindings, int) else sorted(set(bindings))
        n_bindings = len(self.numbers)
        if uniform_binding is not None and uniform_binding in self.numbers:
            raise ValueError(f"uniform binding {uniform_binding} is among the storage buffers' bindings")
        bindings = [vk.VkDescriptorSetLayoutBinding(
            binding=b, descriptorType=vk.VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, descriptorCount=1,
            stageFlags=vk.VK_SHADER_STAGE_COMPUTE_BIT) for b in self.numbers]
        uniforms = [] if uniform_binding is None else [vk.VkDescriptorSetLayoutBinding(
            binding=uniform_binding, descriptorType=vk.VK_DESCRIPTOR_TYPE_UNIFORM_BUFFER, descriptorCount=1,
            stageFlags=vk.VK_SHADER_STAGE_COMPUTE_BIT)]
        self.set_layout = vk.vkCreateDescriptorSetLayout(ctx.device, vk.VkDescriptorSetLayoutCreateInfo(
            sType=vk.VK_STRUCTURE_TYPE_DESCRIPTOR_SET_LAYOUT_CREATE_INFO,
            bindingCount=len(bindings + uniforms), pBindings=bindings + uniforms), None)
        ranges = [vk.VkPushConstantRange(stageFlags=vk.VK_SHADER_STAGE_COMPUTE_BIT, offset=0, size=push_size)]
        self.layout = vk.vkCreatePipelineLayout(ctx.device, vk.VkPipelineLayoutCreateInfo(
            sType=vk.VK_STRUCTURE_TYPE_PIPELINE_LAYOUT_CREATE_INFO, setLayoutCount=1,
            pSetLayouts=[self.set_layout], pushConstantRangeCount=1, pPushConstantRanges=ranges), None)
        module = vk.vkCreateShaderModule(ctx.device, vk.VkShaderModuleCreateInfo(
            sType=vk.VK_STRUCTURE_TYPE_SHADER_MODULE_CREATE_INFO, codeSize=len(spirv), pCode=spirv), None)
        # constant 0: the work-group size; then (constant_id, value) pairs, each 32 bits
        # (VkBool32 for a bool constant). Entries for ids a shader does not declare are ignored.
        constants = [(0, local_size)] + self.spec_values
        self._spec_data = np.array([v for _, v in constants], np.uint32)  # kept alive until the pipeline exists
        entries = [vk.VkSpecializationMapEntry(constantID=cid, offset=4 * k, size=4) for k, (cid, _) in enumerate(constants)]
        spec = vk.VkSpecializationInfo(mapEntryCount=len(entries), pMapEntries=entries,
                                       dataSize=self._spec_data.nbytes, pData=vk.ffi.from_buffer(self._spec_data))
        stage = vk.VkPipelineShaderStageCreateInfo(
            sType=vk.VK_STRUCTURE_TYPE_PIPELINE_SHADER_STAGE_CREATE_INFO, stage=vk.VK_SHADER_STAGE_COMPUTE_BIT,
            module=module, pName="main", pSpecializationInfo=spec)
        self.pipeline = vk.vkCreateComputePipelines(ctx.device, None, 1, [vk.VkComputePipelineCreateInfo(
            sType=vk.VK_STRUCTURE_TYPE_COMPUTE_PIPELINE_CREATE_INFO, stage=stage, layout=self.layout)], None)[0]
        vk.vkDestroyShaderModule(ctx.device, module, None)
        pool_sizes = [vk.VkDescriptorPoolSize(type=vk.VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, descriptorCount=n_bindings)]
        if uniform_binding is not None:
            pool_sizes.append(vk.VkDescriptorPoolSize(type=vk.VK_DESCRIPTOR_TYPE_UNIFORM_BUFFER, descriptorCount=1))
        self.pool = vk.vkCreateDescriptorPool(ctx.device, vk.VkDescriptorPoolCreateInfo(
            sType=vk.VK_STRUCTURE_TYPE_DESCRIPTOR_POOL_CREATE_INFO, maxSets=1, poolSizeCount=len(pool_sizes),
            pPoolSizes=pool_sizes), None)
        self.descriptor_set = vk.vkAllocateDescriptorSets(ctx.device, vk.VkDescriptorSetAllocateInfo(
            sType=vk.VK_STRUCTURE_TYPE_DESCRIPTOR_SET_ALLOCATE_INFO, descriptorPool=self.pool,
            descriptorSetCount=1, pSetLayouts=[self.set_layout]))[0]

    def bind(self, buffers, uniform=None):
        """Bind `buffers` (a list: to the pipeline's binding numbers in order; a dict: binding number -> buffer)
        to the descriptor set, and `uniform` to the uniform binding."""
        vk = self.ctx.vk
        pairs = buffers.items() if isinstance(buffers, dict) else zip(self.numbers, buffers)
        kinds = [(b, buf, vk.VK_DESCRIPTOR_TYPE_STORAGE_BUFFER) for b, buf in pairs]
        if uniform is not None:
            kinds.append((self.uniform_binding, uniform, vk.VK_DESCRIPTOR_TYPE_UNIFORM_BUFFER))
        writes = [vk.VkWriteDescriptorSet(
            sType=vk.VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET, dstSet=self.descriptor_set, dstBinding=b,
            dstArrayElement=0, descriptorCount=1, descriptorType=kind,
            pBufferInfo=[vk.VkDescriptorBufferInfo(buffer=buf.buffer, offset=0, range=WHOLE_SIZE)])
            for b, buf, kind in kinds]
        self.ctx.settle()  # (a descriptor set a submission left running uses is not updated)
        vk.vkUpdateDescriptorSets(self.ctx.device, len(writes), writes, 0, None)

    def free(self):
        vk, dev = self.ctx.vk, self.ctx.device
        vk.vkDestroyDescriptorPool(dev, self.pool, None)
        vk.vkDestroyPipeline(dev, self.pipeline, None)
        vk.vkDestroyPipelineLayout(dev, self.layout, None)
        vk.vkDestroyDescriptorSetLayout(dev, self.set_layout, None)


class Recording:
    """Commands recorded into one primary command buffer, which `Context.submit` runs; or with `secondary`,
    into a secondary one, which primaries run (`execute`), as often as they like."""

    def __init__(self, ctx, secondary=False):
        vk = ctx.vk
        self.ctx = ctx
        level = vk.VK_COMMAND_BUFFER_LEVEL_SECONDARY if secondary else vk.VK_COMMAND_BUFFER_LEVEL_PRIMARY
        self.command_buffer = vk.vkAllocateCommandBuffers(ctx.device, vk.VkCommandBufferAllocateInfo(
            sType=vk.VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO, commandPool=ctx.command_pool,
            level=level, commandBufferCount=1))[0]
        begin = vk.VkCommandBufferBeginInfo(sType=vk.VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO)
        if secondary:  # (several times in one primary: simultaneous use)
            begin = vk.VkCommandBufferBeginInfo(
                sType=vk.VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO,
                flags=vk.VK_COMMAND_BUFFER_USAGE_SIMULTANEOUS_USE_BIT,
                pInheritanceInfo=vk.VkCommandBufferInheritanceInfo(
                    sType=vk.VK_STRUCTURE_TYPE_COMMAND_BUFFER_INHERITANCE_INFO))
        vk.vkBeginCommandBuffer(self.command_buffer, begin)
        self._keep = []

    def execute(self, recordings):
        """Run the finished secondary `recordings`, in order."""
        self._keep.append(recordings)
        self.ctx.vk.vkCmdExecuteCommands(self.command_buffer, len(recordings),
                                         [r.command_buffer for r in recordings])

    def _bind(self, pipeline, push):
        vk, cb = self.ctx.vk, self.command_buffer
        vk.vkCmdBindPipeline(cb, vk.VK_PIPELINE_BIND_POINT_COMPUTE, pipeline.pipeline)
        vk.vkCmdBindDescriptorSets(cb, vk.VK_PIPELINE_BIND_POINT_COMPUTE, pipeline.layout, 0, 1,
                                   [pipeline.descriptor_set], 0, None)
        data = np.ascontiguousarray(push)
        self._keep.append(data)
        vk.vkCmdPushConstants(cb, pipeline.layout, vk.VK_SHADER_STAGE_COMPUTE_BIT, 0, data.nbytes,
                              vk.ffi.from_buffer(data))

    def dispatch(self, pipeline, push, n_invocations=None, groups=None, predicate=None):
        """Bind `pipeline`, push the bytes of `push` and dispatch enough groups for n invocations
        (or `groups`, an (x, y, z) triple); with `predicate`, a (buffer, byte offset), only where the
        32-bit word there is not 0 when the dispatch runs (conditional rendering); (buffer, byte offset, True):
        only where it is 0."""
        self._bind(pipeline, push)
        if groups is None:
            groups = ((int(n_invocations) + pipeline.local_size - 1) // pipeline.local_size, 1, 1)
        if min(groups) > 0:
            self.begin_conditional(predicate)
            self.ctx.vk.vkCmdDispatch(self.command_buffer, *(int(g) for g in groups))
            self.end_conditional(predicate)

    def dispatch_indirect(self, pipeline, push, buffer, offset=0, predicate=None):
        """Dispatch with the (x, y, z) group counts that `buffer` holds at byte `offset` when it runs
        (`predicate`: as dispatch's)."""
        self._bind(pipeline, push)
        self.begin_conditional(predicate)
        self.ctx.vk.vkCmdDispatchIndirect(self.command_buffer, buffer.buffer, offset)
        self.end_conditional(predicate)

    def begin_conditional(self, predicate):
        """The dispatches recorded from here to end_conditional run only where `predicate` holds when this runs
        (a (buffer, byte offset[, inverted]) as dispatch's; None: always). Barriers in between always run."""
        if predicate is not None:
            vk = self.ctx.vk
            buffer, offset, inverted = (*predicate, False)[:3]
            flags = vk.VK_CONDITIONAL_RENDERING_INVERTED_BIT_EXT if inverted else 0
            self.ctx.cmd_begin_conditional(self.command_buffer, vk.VkConditionalRenderingBeginInfoEXT(
                sType=vk.VK_STRUCTURE_TYPE_CONDITIONAL_RENDERING_BEGIN_INFO_EXT, buffer=buffer.buffer, offset=offset,
                flags=flags))

    def end_conditional(self, predicate):
        if predicate is not None:
            self.ctx.cmd_end_conditional(self.command_buffer)

    def fill(self, buffer, value=0):
        """Set every 32-bit word of `buffer` to `value`."""
        vk = self.ctx.vk
        vk.vkCmdFillBuffer(self.command_buffer, buffer.buffer, 0, WHOLE_SIZE, value)
        barrier = vk.VkMemoryBarrier(sType=vk.VK_STRUCTURE_TYPE_MEMORY_BARRIER,
                                     srcAccessMask=vk.VK_ACCESS_TRANSFER_WRITE_BIT,
                                     dstAccessMask=vk.VK_ACCESS_SHADER_READ_BIT | vk.VK_ACCESS_SHADER_WRITE_BIT)
        vk.vkCmdPipelineBarrier(self.command_buffer, vk.VK_PIPELINE_STAGE_TRANSFER_BIT,
                                vk.VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, 0, 1, [barrier], 0, None, 0, None)

    def barrier(self, commands=True):
        """Make every shader write so far visible to every later shader read and write; with `commands`, also to
        the commands that read buffers themselves: indirect dispatches and predicates. Without, the barrier waits
        for the compute stage only (the H200's WCSPH step at 65,536 particles took 0.172 ms with every barrier
        for commands, 0.138 ms with them only where needed: benchmarks/results/archive/ab_barriers_h200/)."""
        vk = self.ctx.vk
        access = vk.VK_ACCESS_SHADER_READ_BIT | vk.VK_ACCESS_SHADER_WRITE_BIT
        stages = vk.VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT
        if commands:
            access |= vk.VK_ACCESS_INDIRECT_COMMAND_READ_BIT
            stages |= vk.VK_PIPELINE_STAGE_DRAW_INDIRECT_BIT
        if commands and self.ctx.conditional_rendering:
            access |= vk.VK_ACCESS_CONDITIONAL_RENDERING_READ_BIT_EXT
            stages |= vk.VK_PIPELINE_STAGE_CONDITIONAL_RENDERING_BIT_EXT
        barrier = vk.VkMemoryBarrier(sType=vk.VK_STRUCTURE_TYPE_MEMORY_BARRIER,
                                     srcAccessMask=vk.VK_ACCESS_SHADER_WRITE_BIT, dstAccessMask=access)
        vk.vkCmdPipelineBarrier(self.command_buffer, vk.VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, stages,
                                0, 1, [barrier], 0, None, 0, None)

    def after_earlier(self):
        """Have every later command wait for every earlier one (of earlier submissions too: a barrier's scope is the
        submission order), their shader and copy writes visible to it; a submission's first commands, behind one
        left running."""
        vk = self.ctx.vk
        stages = vk.VK_PIPELINE_STAGE_TRANSFER_BIT | vk.VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT
        barrier = vk.VkMemoryBarrier(
            sType=vk.VK_STRUCTURE_TYPE_MEMORY_BARRIER,
            srcAccessMask=vk.VK_ACCESS_SHADER_WRITE_BIT | vk.VK_ACCESS_TRANSFER_WRITE_BIT,
            dstAccessMask=vk.VK_ACCESS_SHADER_READ_BIT | vk.VK_ACCESS_SHADER_WRITE_BIT | vk.VK_ACCESS_UNIFORM_READ_BIT
            | vk.VK_ACCESS_TRANSFER_READ_BIT | vk.VK_ACCESS_TRANSFER_WRITE_BIT)
        vk.vkCmdPipelineBarrier(self.command_buffer, stages, stages, 0, 1, [barrier], 0, None, 0, None)

    def copy(self, src, dst, nbytes):
        """Copy the first `nbytes` of Buffer `src` into Buffer `dst`, visible to every later shader and copy."""
        vk = self.ctx.vk
        vk.vkCmdCopyBuffer(self.command_buffer, src.buffer, dst.buffer, 1, [vk.VkBufferCopy(0, 0, nbytes)])
        self.copies_barrier()

    def copies_barrier(self):
        """Make every copy so far visible to every later shader and copy (the commands of later command buffers of
        the submission too: a barrier's scope is the submission order)."""
        vk = self.ctx.vk
        transfer, compute = vk.VK_PIPELINE_STAGE_TRANSFER_BIT, vk.VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT
        barrier = vk.VkMemoryBarrier(
            sType=vk.VK_STRUCTURE_TYPE_MEMORY_BARRIER, srcAccessMask=vk.VK_ACCESS_TRANSFER_WRITE_BIT,
            dstAccessMask=vk.VK_ACCESS_SHADER_READ_BIT | vk.VK_ACCESS_SHADER_WRITE_BIT | vk.VK_ACCESS_UNIFORM_READ_BIT
            | vk.VK_ACCESS_TRANSFER_READ_BIT | vk.VK_ACCESS_TRANSFER_WRITE_BIT)
        vk.vkCmdPipelineBarrier(self.command_buffer, transfer, transfer | compute, 0, 1, [barrier], 0, None, 0, None)

    def timestamp(self, timer, index):
        """Write the GPU clock into slot `index` of `timer` (a Timer) once every earlier command
        has finished (bottom of the pipe): differences of consecutive slots time what ran between."""
        vk = self.ctx.vk
        if index == 0:  # a timer's slots are reset by the recording that writes them, before the first
            vk.vkCmdResetQueryPool(self.command_buffer, timer.pool, 0, timer.slots)
        vk.vkCmdWriteTimestamp(self.command_buffer, vk.VK_PIPELINE_STAGE_BOTTOM_OF_PIPE_BIT, timer.pool, index)

    def end(self):
        self.ctx.vk.vkEndCommandBuffer(self.command_buffer)
        return self

    def free(self, settle=True):
        if settle:
            self.ctx.settle()
        self.ctx.vk.vkFreeCommandBuffers(self.ctx.device, self.ctx.command_pool, 1, [self.command_buffer])


class Timer:
    """A pool of `slots` GPU timestamps (Recording.timestamp writes them); `seconds()` reads the
    intervals between consecutive slots after the recording ran."""

    def __init__(self, ctx, slots):
        vk = ctx.vk
        if not ctx.timestamps:
            raise VulkanError(f"{ctx.device_name} has no timestamps on its compute queue (timestampValidBits = 0 "
                              "or timestampComputeAndGraphics off): it cannot be profiled per stage")
        self.ctx, self.slots = ctx, slots
        self.pool = vk.vkCreateQueryPool(ctx.device, vk.VkQueryPoolCreateInfo(
            sType=vk.VK_STRUCTURE_TYPE_QUERY_POOL_CREATE_INFO, queryType=vk.VK_QUERY_TYPE_TIMESTAMP,
            queryCount=slots), None)

    def seconds(self, count=None):
        """The count - 1 intervals between the first `count` slots [s] (as float64)."""
        vk, count = self.ctx.vk, count or self.slots
        data = vk.ffi.new("uint64_t[]", count)
        vk.vkGetQueryPoolResults(self.ctx.device, self.pool, 0, count, 8 * count, data, 8,
                                 vk.VK_QUERY_RESULT_64_BIT | vk.VK_QUERY_RESULT_WAIT_BIT)
        ticks = np.frombuffer(vk.ffi.buffer(data), np.uint64).astype(np.int64)
        if self.ctx.timestamp_bits < 64:  # the clock wraps at 2^bits
            ticks = np.mod(ticks, 1 << self.ctx.timestamp_bits)
        return np.diff(ticks) * (self.ctx.timestamp_period * 1e-9)

    def free(self):
        self.ctx.vk.vkDestroyQueryPool(self.ctx.device, self.pool, None)


class Context:
    """One Vulkan device with a compute queue.

    device: None (a discrete GPU if present, else the best other), an index into the
    physical-device list, or a substring of the device name; $SPHCORE_VK_DEVICE sets it too.
    validation: enable VK_LAYER_KHRONOS_validation and collect its messages in
    `self.validation_messages` ($SPHCORE_VK_VALIDATION=1 sets it too).
    float64: the shaders will use doubles (physics.precision = "float64"): a device without
    shaderFloat64 is a VulkanError. The feature is enabled wherever the device has it.
    """

    def __init__(self, device=None, validation=None, float64=False):
        self.vk = vk = load_vulkan()
        if device is None:
            device = os.environ.get("SPHCORE_VK_DEVICE") or None
        if validation is None:
            validation = os.environ.get("SPHCORE_VK_VALIDATION", "") not in ("", "0")
        key = self.validation = bool(validation)
        if key not in _INSTANCES:
            self._instance_messages = []
            _INSTANCES[key] = (self._create_instance(validation), self._instance_messages)
        self.instance, self._instance_messages = _INSTANCES[key]
        self._first_message = len(self._instance_messages)
        self.physical_device = self._choose_device(device)
        props = vk.vkGetPhysicalDeviceProperties(self.physical_device)
        self.device_name = _text(props.deviceName)
        self.device_type = self._type_name(props.deviceType)
        self.max_storage_buffer_range = int(props.limits.maxStorageBufferRange)
        self.shader_float64 = self._supports_float64()
        self.subgroup_operations = self._supports_subgroup_operations()
        if float64 and not self.shader_float64:
            raise VulkanError(f"{self.device_name} has no float64 in shaders (shaderFloat64): set "
                              'physics.precision = "float32", pick another device, or run with --backend numba')
        self.memory_properties = vk.vkGetPhysicalDeviceMemoryProperties(self.physical_device)
        families = vk.vkGetPhysicalDeviceQueueFamilyProperties(self.physical_device)
        self.queue_family = next(i for i, f in enumerate(families) if f.queueFlags & vk.VK_QUEUE_COMPUTE_BIT)
        # GPU timestamps (Timer): nanoseconds per tick, and the valid bits of the compute queue's clock
        self.timestamp_period = float(props.limits.timestampPeriod)
        self.timestamp_bits = int(families[self.queue_family].timestampValidBits)
        self.timestamps = bool(self.timestamp_bits and props.limits.timestampComputeAndGraphics)
        queue_info = vk.VkDeviceQueueCreateInfo(
            sType=vk.VK_STRUCTURE_TYPE_DEVICE_QUEUE_CREATE_INFO, queueFamilyIndex=self.queue_family,
            queueCount=1, pQueuePriorities=[1.0])
        features = vk.VkPhysicalDeviceFeatures(shaderFloat64=self.shader_float64)
        # conditional rendering, where the device has it: dispatches skipped by a word in a buffer (the
        # DFSPH host's windows, sphcore.backends.VulkanBackend)
        extensions = {_text(e.extensionName)
                      for e in vk.vkEnumerateDeviceExtensionProperties(self.physical_device, None)}
        self.conditional_rendering = CONDITIONAL_RENDERING in extensions
        # host memory the device copies to and from directly, where it can (host_buffer: a rank's exchange)
        self.host_memory = HOST_MEMORY in extensions
        # memory another API of this process imports (exported_buffer: CUDA's, for a rank's copies to its peers)
        self.memory_fd = MEMORY_FD in extensions
        enabled, chain = [HOST_MEMORY] if self.host_memory else [], vk.ffi.NULL
        if self.memory_fd:
            enabled.append(MEMORY_FD)
        if self.conditional_rendering:
            enabled.append(CONDITIONAL_RENDERING)
            chain = vk.VkPhysicalDeviceConditionalRenderingFeaturesEXT(
                sType=vk.VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_CONDITIONAL_RENDERING_FEATURES_EXT, conditionalRendering=1)
        self.device = vk.vkCreateDevice(self.physical_device, vk.VkDeviceCreateInfo(
            sType=vk.VK_STRUCTURE_TYPE_DEVICE_CREATE_INFO, pNext=chain, queueCreateInfoCount=1,
            pQueueCreateInfos=[queue_info], enabledExtensionCount=len(enabled), ppEnabledExtensionNames=enabled,
            pEnabledFeatures=features), None)
        if self.conditional_rendering:
            self.cmd_begin_conditional = vk.vkGetDeviceProcAddr(self.device, "vkCmdBeginConditionalRenderingEXT")
            self.cmd_end_conditional = vk.vkGetDeviceProcAddr(self.device, "vkCmdEndConditionalRenderingEXT")
        if self.host_memory:
            self.host_pointer_properties = vk.vkGetDeviceProcAddr(self.device, "vkGetMemoryHostPointerPropertiesEXT")
            host = vk.VkPhysicalDeviceExternalMemoryHostPropertiesEXT(
                sType=vk.VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_EXTERNAL_MEMORY_HOST_PROPERTIES_EXT)
            vk.vkGetPhysicalDeviceProperties2(self.physical_device, vk.VkPhysicalDeviceProperties2(
                sType=vk.VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_PROPERTIES_2, pNext=host))
            self.host_alignment = int(host.minImportedHostPointerAlignment)  # (4 KiB on NVIDIA's and lavapipe)
        if self.memory_fd:
            self.get_memory_fd = vk.vkGetDeviceProcAddr(self.device, "vkGetMemoryFdKHR")
        ids = vk.VkPhysicalDeviceIDProperties(sType=vk.VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_ID_PROPERTIES)
        vk.vkGetPhysicalDeviceProperties2(self.physical_device, vk.VkPhysicalDeviceProperties2(
            sType=vk.VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_PROPERTIES_2, pNext=ids))
        self.device_uuid = bytes(vk.ffi.buffer(ids.deviceUUID))  # (CUDA's cuDeviceGetUuid of the same device)
        self.queue = vk.vkGetDeviceQueue(self.device, self.queue_family, 0)
        self.command_pool = vk.vkCreateCommandPool(self.device, vk.VkCommandPoolCreateInfo(
            sType=vk.VK_STRUCTURE_TYPE_COMMAND_POOL_CREATE_INFO, queueFamilyIndex=self.queue_family,
            flags=vk.VK_COMMAND_POOL_CREATE_RESET_COMMAND_BUFFER_BIT), None)
        self.fence = self._new_fence()
        self.running = []  # (the submissions left running, oldest first: submit's wait=False; their fences, and the
        self.fences = []  # recordings to free once each is done) and the fences free for more
        self.first = []  # (recordings the next submission runs before its own: queue_first)
        self._kept_staging = {}  # (_staging: a buffer kept for each use)

    # ---- instance and device ----
    def _create_instance(self, validation):
        vk = self.vk
        layers, extensions = [], []
        if validation:
            available = {_text(p.layerName) for p in vk.vkEnumerateInstanceLayerProperties()}
            if VALIDATION_LAYER not in available:
                raise VulkanError(f"validation requested but {VALIDATION_LAYER} is not installed: "
                                  "apt-get install vulkan-validationlayers")
            layers, extensions = [VALIDATION_LAYER], ["VK_EXT_debug_utils"]
        app = vk.VkApplicationInfo(sType=vk.VK_STRUCTURE_TYPE_APPLICATION_INFO, pApplicationName="sphcore",
                                   applicationVersion=1, pEngineName="sphcore", engineVersion=1,
                                   apiVersion=vk.VK_MAKE_VERSION(1, 1, 0))
        try:
            instance = vk.vkCreateInstance(vk.VkInstanceCreateInfo(
                sType=vk.VK_STRUCTURE_TYPE_INSTANCE_CREATE_INFO, pApplicationInfo=app,
                enabledLayerCount=len(layers), ppEnabledLayerNames=layers,
                enabledExtensionCount=len(extensions), ppEnabledExtensionNames=extensions), None)
        except (vk.VkErrorIncompatibleDriver, vk.VkErrorInitializationFailed) as e:
            raise VulkanError(f"no Vulkan driver could be loaded ({type(e).__name__}): apt-get install "
                              "mesa-vulkan-drivers for lavapipe on the CPU, or install your GPU's driver; "
                              "or run with --backend numba") from None
        if validation:
            def on_message(severity, kind, data, user):
                if severity & vk.VK_DEBUG_UTILS_MESSAGE_SEVERITY_ERROR_BIT_EXT:
                    text = _text(data.pMessage)
                    self._instance_messages.append(text)
                    print(f"sphcore: Vulkan validation: {text}", file=sys.stderr, flush=True)  # as it comes
                return 0

            create = vk.vkGetInstanceProcAddr(instance, "vkCreateDebugUtilsMessengerEXT")
            messenger = create(instance, vk.VkDebugUtilsMessengerCreateInfoEXT(
                sType=vk.VK_STRUCTURE_TYPE_DEBUG_UTILS_MESSENGER_CREATE_INFO_EXT,
                messageSeverity=(vk.VK_DEBUG_UTILS_MESSAGE_SEVERITY_WARNING_BIT_EXT
                                 | vk.VK_DEBUG_UTILS_MESSAGE_SEVERITY_ERROR_BIT_EXT),
                messageType=(vk.VK_DEBUG_UTILS_MESSAGE_TYPE_GENERAL_BIT_EXT
                             | vk.VK_DEBUG_UTILS_MESSAGE_TYPE_VALIDATION_BIT_EXT),
                pfnUserCallback=on_message), None)
            _CALLBACKS.append((on_message, messenger))
        return instance

    def _supports_float64(self):
        """Whether the chosen device runs shaders with doubles (feature shaderFloat64)."""
        return bool(self.vk.vkGetPhysicalDeviceFeatures(self.physical_device).shaderFloat64)

    def _supports_subgroup_operations(self):
        """Whether compute shaders on the chosen device have the subgroup operations the per-cube
        marching cubes uses (basic, arithmetic, ballot, shuffle; Vulkan 1.1's subgroup properties)."""
        vk = self.vk
        subgroup = vk.VkPhysicalDeviceSubgroupProperties(sType=vk.VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_SUBGROUP_PROPERTIES)
        vk.vkGetPhysicalDeviceProperties2(self.physical_device, vk.VkPhysicalDeviceProperties2(
            sType=vk.VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_PROPERTIES_2, pNext=subgroup))
        wanted = (vk.VK_SUBGROUP_FEATURE_BASIC_BIT | vk.VK_SUBGROUP_FEATURE_ARITHMETIC_BIT
                  | vk.VK_SUBGROUP_FEATURE_BALLOT_BIT | vk.VK_SUBGROUP_FEATURE_SHUFFLE_BIT)
        return bool(subgroup.supportedStages & vk.VK_SHADER_STAGE_COMPUTE_BIT
                    and subgroup.supportedOperations & wanted == wanted)

    def _type_name(self, device_type):
        vk = self.vk
        return {vk.VK_PHYSICAL_DEVICE_TYPE_DISCRETE_GPU: "DISCRETE_GPU",
                vk.VK_PHYSICAL_DEVICE_TYPE_INTEGRATED_GPU: "INTEGRATED_GPU",
                vk.VK_PHYSICAL_DEVICE_TYPE_VIRTUAL_GPU: "VIRTUAL_GPU",
                vk.VK_PHYSICAL_DEVICE_TYPE_CPU: "CPU"}.get(device_type, "OTHER")

    def _choose_device(self, wanted):
        vk = self.vk
        try:
            devices = list(vk.vkEnumeratePhysicalDevices(self.instance))
        except vk.VkErrorInitializationFailed:
            devices = []
        if not devices:
            raise VulkanError("no Vulkan device found (the loader found no driver): apt-get install "
                              "mesa-vulkan-drivers for lavapipe on the CPU, or install your GPU's driver "
                              "(check with vulkaninfo --summary); or run with --backend numba")
        props = [vk.vkGetPhysicalDeviceProperties(d) for d in devices]
        names = [_text(p.deviceName) for p in props]
        if wanted is None:
            rank = [DEVICE_TYPE_RANK.index(self._type_name(p.deviceType)) for p in props]
            return devices[rank.index(min(rank))]
        if str(wanted).isdigit() and int(wanted) < len(devices):
            return devices[int(wanted)]
        for d, name in zip(devices, names):
            if str(wanted).lower() in name.lower():
                return d
        raise VulkanError(f"no Vulkan device matches {wanted!r}; available: "
                          + ", ".join(f"[{i}] {n}" for i, n in enumerate(names)))

    # ---- memory ----
    def _allocate(self, nbytes, usage, wanted_flags, name, preferred_flags=0):
        """A buffer of `nbytes` in the first memory type with `wanted_flags`, the first with `preferred_flags` too
        where there is one."""
        vk = self.vk
        props = self.memory_properties
        host = vk.VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | vk.VK_MEMORY_PROPERTY_HOST_COHERENT_BIT
        limit = self.max_storage_buffer_range
        if usage & vk.VK_BUFFER_USAGE_STORAGE_BUFFER_BIT and nbytes > limit:
            raise VulkanError(f"out of device memory: buffer '{name}' needs {nbytes / 2**20:.1f} MiB, more than "
                              f"this device's largest storage buffer ({limit / 2**20:.1f} MiB on {self.device_name}); "
                              "use fewer particles or a coarser grid, or --backend numba")
        buffer = vk.vkCreateBuffer(self.device, vk.VkBufferCreateInfo(
            sType=vk.VK_STRUCTURE_TYPE_BUFFER_CREATE_INFO, size=nbytes, usage=usage,
            sharingMode=vk.VK_SHARING_MODE_EXCLUSIVE), None)
        req = vk.vkGetBufferMemoryRequirements(self.device, buffer)
        types = [(i, props.memoryTypes[i].propertyFlags) for i in range(props.memoryTypeCount)
                 if req.memoryTypeBits & (1 << i) and props.memoryTypes[i].propertyFlags & wanted_flags == wanted_flags]
        if not types:
            vk.vkDestroyBuffer(self.device, buffer, None)
            raise VulkanError(f"no memory type with flags {wanted_flags:#x} for buffer '{name}' on {self.device_name}")
        index, flags = next((t for t in types if t[1] & preferred_flags == preferred_flags), types[0])
        heap = props.memoryHeaps[props.memoryTypes[index].heapIndex].size
        try:
            if req.size > heap:
                raise vk.VkErrorOutOfDeviceMemory()
            memory = vk.vkAllocateMemory(self.device, vk.VkMemoryAllocateInfo(
                sType=vk.VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO, allocationSize=req.size,
                memoryTypeIndex=index), None)
        except (vk.VkErrorOutOfDeviceMemory, vk.VkErrorOutOfHostMemory):
            vk.vkDestroyBuffer(self.device, buffer, None)
            raise VulkanError(f"out of device memory: buffer '{name}' needs {req.size / 2**20:.1f} MiB "
                              f"({self.device_name}, heap of {heap / 2**20:.0f} MiB); "
                              "use fewer particles or a coarser grid, or --backend numba") from None
        vk.vkBindBufferMemory(self.device, buffer, memory, 0)
        return buffer, memory, flags & host == host

    def host_buffer(self, address, nbytes, name="host"):
        """A Buffer over `nbytes` of this process's memory from `address` on (VK_EXT_external_memory_host), for
        copies between it and the device's buffers (_copies); None where the device cannot import it: no such
        extension, an address or a size not a multiple of the device's `host_alignment` (never offered: after an
        import of unaligned memory failed, NVIDIA's driver 580 failed every later allocation), or the import failed.
        The memory must outlive the Buffer."""
        if not self.host_memory or address % self.host_alignment or nbytes % self.host_alignment:
            return None
        vk = self.vk
        kind = vk.VK_EXTERNAL_MEMORY_HANDLE_TYPE_HOST_ALLOCATION_BIT_EXT
        pointer = vk.ffi.cast("void *", address)
        buffer = vk.vkCreateBuffer(self.device, vk.VkBufferCreateInfo(
            sType=vk.VK_STRUCTURE_TYPE_BUFFER_CREATE_INFO, size=nbytes, sharingMode=vk.VK_SHARING_MODE_EXCLUSIVE,
            usage=vk.VK_BUFFER_USAGE_TRANSFER_SRC_BIT | vk.VK_BUFFER_USAGE_TRANSFER_DST_BIT,
            pNext=vk.VkExternalMemoryBufferCreateInfo(sType=vk.VK_STRUCTURE_TYPE_EXTERNAL_MEMORY_BUFFER_CREATE_INFO,
                                                      handleTypes=kind)), None)
        try:
            types = self.host_pointer_properties(self.device, kind, pointer).memoryTypeBits
            types &= vk.vkGetBufferMemoryRequirements(self.device, buffer).memoryTypeBits
            memory = vk.vkAllocateMemory(self.device, vk.VkMemoryAllocateInfo(
                sType=vk.VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO, allocationSize=nbytes,
                memoryTypeIndex=(types & -types).bit_length() - 1,
                pNext=vk.VkImportMemoryHostPointerInfoEXT(
                    sType=vk.VK_STRUCTURE_TYPE_IMPORT_MEMORY_HOST_POINTER_INFO_EXT, handleType=kind,
                    pHostPointer=pointer)), None)
            vk.vkBindBufferMemory(self.device, buffer, memory, 0)
        except (vk.VkError, vk.VkException):
            vk.vkDestroyBuffer(self.device, buffer, None)
            return None
        return Buffer.bound(self, nbytes, name, buffer, memory)

    def exported_buffer(self, nbytes, name="exported"):
        """A Buffer of `nbytes` of device memory that another API imports (VK_KHR_external_memory_fd: a dedicated
        allocation, exported as an opaque file descriptor), for copies between it and the device's buffers
        (_copies); with the descriptor (the importer's to close) and the allocation's bytes. None where the device
        cannot export."""
        if not self.memory_fd:
            return None
        vk = self.vk
        kind = vk.VK_EXTERNAL_MEMORY_HANDLE_TYPE_OPAQUE_FD_BIT
        buffer = vk.vkCreateBuffer(self.device, vk.VkBufferCreateInfo(
            sType=vk.VK_STRUCTURE_TYPE_BUFFER_CREATE_INFO, size=nbytes, sharingMode=vk.VK_SHARING_MODE_EXCLUSIVE,
            usage=vk.VK_BUFFER_USAGE_TRANSFER_SRC_BIT | vk.VK_BUFFER_USAGE_TRANSFER_DST_BIT
            | vk.VK_BUFFER_USAGE_STORAGE_BUFFER_BIT,
            pNext=vk.VkExternalMemoryBufferCreateInfo(sType=vk.VK_STRUCTURE_TYPE_EXTERNAL_MEMORY_BUFFER_CREATE_INFO,
                                                      handleTypes=kind)), None)
        req = vk.vkGetBufferMemoryRequirements(self.device, buffer)
        props, local = self.memory_properties, vk.VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT
        index = next((i for i in range(props.memoryTypeCount)
                      if req.memoryTypeBits & (1 << i) and props.memoryTypes[i].propertyFlags & local), None)
        try:
            if index is None:
                raise vk.VkErrorOutOfDeviceMemory()
            memory = vk.vkAllocateMemory(self.device, vk.VkMemoryAllocateInfo(
                sType=vk.VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO, allocationSize=req.size, memoryTypeIndex=index,
                pNext=vk.VkExportMemoryAllocateInfo(
                    sType=vk.VK_STRUCTURE_TYPE_EXPORT_MEMORY_ALLOCATE_INFO, handleTypes=kind,
                    pNext=vk.VkMemoryDedicatedAllocateInfo(
                        sType=vk.VK_STRUCTURE_TYPE_MEMORY_DEDICATED_ALLOCATE_INFO, buffer=buffer))), None)
        except (vk.VkError, vk.VkException):
            vk.vkDestroyBuffer(self.device, buffer, None)
            return None
        vk.vkBindBufferMemory(self.device, buffer, memory, 0)
        fd = self.get_memory_fd(self.device, vk.VkMemoryGetFdInfoKHR(
            sType=vk.VK_STRUCTURE_TYPE_MEMORY_GET_FD_INFO_KHR, memory=memory, handleType=kind))
        return Buffer.bound(self, nbytes, name, buffer, memory), fd, int(req.size)

    def _map(self, memory, nbytes, offset=0):
        vk = self.vk
        try:
            return vk.vkMapMemory(self.device, memory, offset, nbytes, 0)
        except (vk.VkErrorMemoryMapFailed, vk.VkErrorDeviceLost, vk.VkErrorOutOfHostMemory) as e:
            raise VulkanError(f"could not map {nbytes / 2**20:.1f} MiB of memory on {self.device_name} "
                              f"({type(e).__name__}): use fewer particles or --backend numba") from None

    def _staging(self, nbytes, use="copy", most=STAGING_MOST):
        """Host-visible memory for a copy of `nbytes`: one buffer kept for each `use` (copies, the rows read
        back and written by read_regions and write_regions) for every copy up to `most` bytes, grown to the
        largest so far (allocating memory took about 2 ms a copy on an NVIDIA driver; the DFSPH host reads its
        control words after every submission, a rank of sphcore.parallel its halo every step)."""
        if nbytes > most:
            return _Staging(self, nbytes)
        kept = self._kept_staging.get(use)
        if kept is None or kept.nbytes < nbytes:
            if kept is not None:
                kept.free()
            kept = self._kept_staging[use] = _Staging(self, max(nbytes, STAGING_KEPT))
        return kept

    def _release(self, staging):
        if staging not in self._kept_staging.values():
            staging.free()

    def _copy(self, src, dst, regions):
        """Copy (source offset, destination offset, bytes) `regions` from buffer `src` to `dst`, and wait."""
        self._copies([(src, dst, regions)])

    def _copies(self, copies, then=None, wait=True):
        """Run the buffer copies `copies` ((src, dst, regions) each, as _copy's) in one submission, and wait (`wait`
        False: submit's); with `then` (a finished Recording), it runs after the copies in the same submission, their
        writes visible to it."""
        grouped = {}  # (one command a pair of buffers: a command took 7 us of Python)
        for src, dst, regions in copies:
            grouped.setdefault((src, dst), []).extend(regions)
        rec = Recording(self)
        rec.after_earlier()  # (behind a submission left running)
        for (src, dst), regions in grouped.items():
            # (the regions written through numpy: a VkBufferCopy made one by one took 7 us of Python, 2 ms for the
            # 300 regions a rank of sphcore.parallel once read every step)
            array = self.vk.ffi.new("VkBufferCopy[]", len(regions))
            np.frombuffer(self.vk.ffi.buffer(array), np.uint64).reshape(-1, 3)[:] = regions
            self.vk.vkCmdCopyBuffer(rec.command_buffer, src, dst, len(regions), array)
        if then is not None:
            rec.copies_barrier()
        self.submit(rec.end(), *([then] if then is not None else []), wait=wait, keep=() if wait else [rec])
        if wait:
            rec.free()

    # ---- public ----
    def read_regions(self, copies, nbytes, into=None):
        """`nbytes` bytes read back from buffers in one submission, for each (Buffer, its byte offset, the byte
        offset in the result, byte count) of `copies`: into Buffer `into` (host_buffer's), or else a view (uint8)
        of host memory that the next read_regions overwrites (copy what is kept longer)."""
        target = into or self._staging(nbytes, "read_regions", math.inf)
        self._copies([(buffer.buffer, target.buffer, [(offset, at, count)])
                      for buffer, offset, at, count in copies if count])
        return None if into else target.bytes[:nbytes]

    def space_to_write(self, nbytes):
        """Host memory of `nbytes` (uint8) for write_regions' `data`: filled there, it is not copied again."""
        return self._staging(nbytes, "write_regions", math.inf).bytes[:nbytes]

    def write_regions(self, data, copies):
        """Write bytes of `data` into buffers in one submission, for each (Buffer, the byte offset in `data`, the
        buffer's byte offset, byte count) of `copies`: `data` a Buffer (host_buffer's), or host memory (uint8; best
        space_to_write's)."""
        self.write_parts([(data, copies)])

    def write_parts(self, parts, copies_first=(), then=None, wait=True):
        """write_regions of each (data, copies) of `parts`, in one submission: each `data` a Buffer, or one host
        array (uint8) for them all; with the buffer copies `copies_first` (_copies') where given, of bytes the
        writes do not touch; and `then` (a finished Recording) after them in that submission (_copies; `wait`:
        submit's, where no part is host memory)."""
        commands, staged = list(copies_first), None
        for data, copies in parts:
            copies = [c for c in copies if c[3]]
            for buffer, _, offset, count in copies:
                if offset + count > buffer.nbytes:
                    raise ValueError(f"{buffer.name}: {count} bytes at {offset} do not fit in {buffer.nbytes}")
            source = data
            if copies and not isinstance(data, Buffer):
                if staged is None:
                    staged = data, self._staging(data.nbytes, "write_regions", math.inf)
                    if not (len(data) and data.ctypes.data == staged[1].bytes.ctypes.data):
                        staged[1].bytes[:data.nbytes] = data.reshape(-1).view(np.uint8)
                elif staged[0] is not data:
                    raise ValueError("write_parts takes one host array for all its parts (else Buffers)")
                source = staged[1]
            commands += [(source.buffer, buffer.buffer, [(at, offset, count)]) for buffer, at, offset, count in copies]
        if commands:  # (one that reads the kept staging buffer waited for: space_to_write hands it out again)
            self._copies(commands, then, wait or staged is not None)
        elif then is not None:
            self.submit(then, wait=wait)

    def buffer(self, nbytes, name="buffer", uniform=False, mapped=False):
        return Buffer(self, nbytes, name, uniform, mapped)

    def pipeline(self, spirv, bindings, push_size, local_size=128, spec_values=(), uniform_binding=None):
        return Pipeline(self, spirv, bindings, push_size, local_size, spec_values, uniform_binding)

    def record(self, secondary=False):
        return Recording(self, secondary)

    def timer(self, slots):
        return Timer(self, slots)

    def submit(self, *recordings, wait=True, keep=()):
        """Run finished recordings, in order, in one submission (queue_first's first) and wait for it; with `wait`
        False, leave it running (the recordings of `keep` freed once it is done): every later call that reads or
        writes the device's memory from the host, updates a descriptor set or frees what it may use waits for it
        first (settle). A later submission runs after it (each recording ends with a barrier; queue_first's begins
        with one)."""
        vk = self.vk
        recordings, self.first = self.first + list(recordings), []
        fence = self.fence if wait else self.fences.pop() if self.fences else self._new_fence()
        try:
            vk.vkQueueSubmit(self.queue, 1, [vk.VkSubmitInfo(
                sType=vk.VK_STRUCTURE_TYPE_SUBMIT_INFO, commandBufferCount=len(recordings),
                pCommandBuffers=[recording.command_buffer for recording in recordings])], fence)
        except (vk.VkError, vk.VkException) as e:
            self._failed(e)
        if wait:
            self._wait(self.fence)
        else:
            self.running.append((fence, keep))

    def queue_first(self, recording):
        """Have the next submission run `recording` (a finished one, kept by the caller) before its own."""
        self.first.append(recording)

    def settle(self, keep=0):
        """Wait for the submissions left running (submit's wait=False), all but the last `keep` of them."""
        while len(self.running) > keep:
            fence, recordings = self.running.pop(0)
            self._wait(fence)
            self.fences.append(fence)
            for recording in recordings:
                recording.free(settle=False)

    def _new_fence(self):
        return self.vk.vkCreateFence(self.device, self.vk.VkFenceCreateInfo(
            sType=self.vk.VK_STRUCTURE_TYPE_FENCE_CREATE_INFO), None)

    def _wait(self, fence):
        """Wait for `fence` (polled a while first on a GPU: a short submission is known done sooner), and reset it."""
        vk = self.vk
        try:
            if self.device_type != "CPU":
                until = time.perf_counter() + SPIN_SECONDS
                while vk.lib.vkGetFenceStatus(self.device, fence) == vk.VK_NOT_READY and time.perf_counter() < until:
                    pass
            vk.vkWaitForFences(self.device, 1, [fence], vk.VK_TRUE, FENCE_TIMEOUT_NS)
        except (vk.VkError, vk.VkException) as e:
            self._failed(e)
        vk.vkResetFences(self.device, 1, [fence])

    def _failed(self, e):
        """The VulkanError of a submission or a wait that raised `e`."""
        vk = self.vk
        if isinstance(e, vk.VkErrorDeviceLost):
            raise VulkanError(f"the Vulkan device was lost ({self.device_name}): its driver reset it (a fault, "
                              "a time-out, or another program); retry, or run with --backend numba") from None
        if isinstance(e, (vk.VkErrorOutOfDeviceMemory, vk.VkErrorOutOfHostMemory)):
            raise VulkanError(f"out of device memory while running on {self.device_name}: "
                              "use fewer particles or --backend numba") from None
        if isinstance(e, vk.VkTimeout):
            raise VulkanError(f"{self.device_name} did not finish one submission in {FENCE_TIMEOUT_NS // 10**9} s: "
                              "use fewer particles or --backend numba") from None
        raise VulkanError(f"running on {self.device_name} failed ({type(e).__name__}): retry, or run with "
                          "--backend numba") from None

    def close(self):
        vk = self.vk
        if getattr(self, "device", None) is None:
            return
        try:
            vk.vkDeviceWaitIdle(self.device)
        except vk.VkErrorDeviceLost:
            pass  # nothing runs on a lost device any more; its objects are destroyed all the same
        for staging in self._kept_staging.values():
            staging.free()
        for fence in [self.fence, *self.fences, *(fence for fence, _ in self.running)]:
            vk.vkDestroyFence(self.device, fence, None)
        vk.vkDestroyCommandPool(self.device, self.command_pool, None)
        vk.vkDestroyDevice(self.device, None)
        self.device = None  # the instance is shared by every Context of this process (see _INSTANCES)

    @property
    def validation_messages(self):
        """Validation-layer errors reported since this Context was created."""
        return self._instance_messages[self._first_message:]

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
