"""Rows sent from one rank's GPU to another's straight from device memory to device memory (CUDA IPC: over NVLink,
or PCIe peer to peer), for sphcore.parallel's exchange where every rank of one host runs on Vulkan on an NVIDIA GPU
and cuda-bindings is installed (`pip install 'sphcore[cuda]'`); elsewhere the rows go through host memory
(parallel.Shared) or MPI.

Each rank holds three regions of its GPU's memory:
  outbox:  Vulkan's, imported into CUDA (Context.exported_buffer): the device packs the rows for the other ranks
           there (read_regions' `into`), as it packs them into host memory otherwise;
  mailbox: CUDA's, which every other rank opens (cuIpcOpenMemHandle): the outbox copied there (publish);
  inbox:   Vulkan's, imported into CUDA: each other rank's rows for this one copied there from its mailbox (pull),
           which the device then writes into the particle buffers (write_parts).
Vulkan and CUDA take turns, each waited for on the host; the barrier between publish and pull is the one wait on
the other ranks (parallel.Rank.swap_peers). A mailbox is written again only after the next step's Allgather, which
every rank reaches after its pull."""
import ctypes
import os

from sphcore.errors import SceneError, SimulationError

GRAIN = 1 << 20  # bytes: the boxes grow by a quarter past what is asked, in whole MiB
HANDLE_BYTES = 64  # a CUipcMemHandle


def room(nbytes):
    """A box's bytes for `nbytes`: a quarter more, in whole GRAINs."""
    return -(-int(nbytes * 1.25) // GRAIN) * GRAIN


def cuda():
    """cuda-bindings' driver module, initialized, and None; or None and why not."""
    try:
        from cuda.bindings import driver
    except ImportError:
        return None, "cuda-bindings is not installed (pip install 'sphcore[cuda]')"
    try:
        (result,) = driver.cuInit(0)
    except Exception as e:  # (cuda-bindings finds no libcuda: no NVIDIA driver)
        return None, f"no CUDA driver ({type(e).__name__})"
    if result != driver.CUresult.CUDA_SUCCESS:
        return None, f"CUDA's cuInit failed ({result.name})"
    return driver, None


class Box:
    """A region of device memory as a Vulkan Buffer (`buffer`, None for a mailbox) and a CUDA pointer."""

    def __init__(self, buffer, memory, pointer, nbytes):
        self.buffer, self.memory, self.pointer, self.nbytes = buffer, memory, pointer, nbytes


class Peers:
    """The boxes of one rank (module docstring) over Vulkan Context `ctx` and the CUDA device of the same UUID."""

    def __init__(self, comm, ctx, cu, device):
        self.comm, self.ctx, self.cu, self.rank = comm, ctx, cu, comm.Get_rank()
        self.context = self.call("cuDevicePrimaryCtxRetain", device)
        self.device = device
        self.call("cuCtxSetCurrent", self.context)
        self.outbox = self.mailbox = self.inbox = None
        self.opened = []  # (the other ranks' mailboxes, by rank; None for this one's)

    @classmethod
    def make(cls, comm, backend, required=False):
        """Peers over `backend`'s device where every rank of `comm` has one (collective), else None; where
        `required` (SPHCORE_MPI_EXCHANGE=cuda) a SceneError naming the first rank that has none, and why."""
        from mpi4py import MPI
        ctx, cu, device, reason = getattr(backend, "ctx", None), None, None, None
        if ctx is None:
            reason = "the numba backend has no GPU memory"
        elif not ctx.memory_fd:
            reason = f"{ctx.device_name} exports no memory (VK_KHR_external_memory_fd)"
        elif comm.Split_type(MPI.COMM_TYPE_SHARED).Get_size() < comm.Get_size():
            reason = "the ranks are on more than one host"
        else:
            cu, reason = cuda()
        if reason is None:
            _, count = cu.cuDeviceGetCount()
            uuids = {bytes(cu.cuDeviceGetUuid(d)[1].bytes): d for d in range(count)}
            device = uuids.get(ctx.device_uuid)
            if device is None:
                reason = f"CUDA finds no device of {ctx.device_name}'s UUID"
        peers = None
        if reason is None:
            try:
                peers = cls(comm, ctx, cu, device)
            except SimulationError as e:
                reason = str(e)
        reasons = comm.allgather(reason)
        if not any(reasons):  # (every rank has its Peers: fit and close are collective)
            try:
                peers.fit(1, 1)
            except SimulationError as e:
                reason = str(e)
            reasons = comm.allgather(reason)
            if any(reasons):
                peers.close()
        elif peers is not None:
            peers.call("cuDevicePrimaryCtxRelease", peers.device)
        failed = next(((q, why) for q, why in enumerate(reasons) if why), None)
        if failed is None:
            return peers
        if required:
            raise SceneError(f"SPHCORE_MPI_EXCHANGE=cuda: rank {failed[0]}: {failed[1]}")
        return None

    def call(self, name, *args):
        """CUDA's `name`(*args): what it returns past its result, or a SimulationError naming it."""
        result, *out = getattr(self.cu, name)(*args)
        if result != self.cu.CUresult.CUDA_SUCCESS:
            raise SimulationError(f"CUDA's {name} failed ({result.name})")
        return out[0] if out else None

    def imported(self, nbytes, name):
        """A Box of `nbytes`: a Vulkan buffer exported, imported into CUDA."""
        made = self.ctx.exported_buffer(nbytes, name)
        if made is None:
            raise SimulationError(f"{self.ctx.device_name} could not export {nbytes} bytes")
        buffer, fd, size = made
        cu = self.cu
        handle = cu.CUDA_EXTERNAL_MEMORY_HANDLE_DESC()
        handle.type = cu.CUexternalMemoryHandleType.CU_EXTERNAL_MEMORY_HANDLE_TYPE_OPAQUE_FD
        handle.handle.fd, handle.size, handle.flags = fd, size, cu.CUDA_EXTERNAL_MEMORY_DEDICATED
        try:
            memory = self.call("cuImportExternalMemory", handle)  # (CUDA owns the descriptor from now on)
        except SimulationError:
            os.close(fd)
            buffer.free()
            raise
        view = cu.CUDA_EXTERNAL_MEMORY_BUFFER_DESC()
        view.offset, view.size = 0, nbytes
        return Box(buffer, memory, self.call("cuExternalMemoryGetMappedBuffer", memory, view), nbytes)

    def free(self, box):
        if box is not None:
            self.call("cuMemFree", box.pointer)
            if box.buffer is not None:
                self.call("cuDestroyExternalMemory", box.memory)
                box.buffer.free()

    def fit(self, send, receive):
        """Room for `send` bytes in the outbox and mailbox (the same on every rank: collective where they grow) and
        `receive` in the inbox, each grown by a quarter past it where there is less."""
        if self.outbox is None or send > self.outbox.nbytes:
            self.close_mailboxes()
            nbytes, handle = room(send), None
            try:
                self.outbox = self.imported(nbytes, "outbox")
                self.mailbox = Box(None, None, self.call("cuMemAlloc", nbytes), nbytes)
                handle = ctypes.string_at(self.call("cuIpcGetMemHandle", self.mailbox.pointer).getPtr(), HANDLE_BYTES)
            except SimulationError as e:
                handle = str(e)
            handles = self.comm.allgather(handle)  # (also where a rank failed: every rank then raises)
            failed = next((f"rank {q}: {h}" for q, h in enumerate(handles) if isinstance(h, str)), None)
            if failed:
                raise SimulationError(failed)
            lazy = self.cu.CUipcMem_flags.CU_IPC_MEM_LAZY_ENABLE_PEER_ACCESS
            self.opened = [None if q == self.rank else self.call("cuIpcOpenMemHandle", self.handle(h), lazy)
                           for q, h in enumerate(handles)]
        if self.inbox is None or receive > self.inbox.nbytes:
            self.free(self.inbox)
            self.inbox = None
            self.inbox = self.imported(room(receive), "inbox")

    def handle(self, data):
        handle = self.cu.CUipcMemHandle()
        ctypes.memmove(handle.getPtr(), data, HANDLE_BYTES)
        return handle

    def publish(self, nbytes):
        """The outbox's first `nbytes` copied into the mailbox, and waited for."""
        if nbytes:
            self.call("cuMemcpyDtoD", self.mailbox.pointer, self.outbox.pointer, nbytes)
        self.call("cuCtxSynchronize")

    def pull(self, sources):
        """For each (rank, byte offset, bytes) of `sources`, that rank's mailbox's bytes copied into the inbox, one
        after the other, and waited for; the offset of each in the inbox."""
        offsets, at = [], 0
        for q, offset, nbytes in sources:
            if nbytes:
                self.call("cuMemcpyDtoD", self.cu.CUdeviceptr(int(self.inbox.pointer) + at),
                          self.cu.CUdeviceptr(int(self.opened[q]) + offset), nbytes)
            offsets.append(at)
            at += nbytes
        self.call("cuCtxSynchronize")
        return offsets

    def close_mailboxes(self):
        """Close the other ranks' mailboxes, and once every rank has (a barrier), free this one's (collective)."""
        for pointer in self.opened:
            if pointer is not None:
                self.call("cuIpcCloseMemHandle", pointer)
        self.opened = []
        self.comm.Barrier()
        self.free(self.outbox)
        self.free(self.mailbox)
        self.outbox = self.mailbox = None

    def close(self):
        """Free every box (collective)."""
        self.close_mailboxes()
        self.free(self.inbox)
        self.inbox = None
        self.call("cuDevicePrimaryCtxRelease", self.device)
