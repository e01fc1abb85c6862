"""One scene on N MPI ranks (issue 34; docs/parallel.md): `mpiexec -n N sphcore run SCENE`, or
`sphcore.parallel.run` under mpiexec, on the numba or the Vulkan backend (rank r of a host on its r-th GPU).

Each rank owns a slab of the domain (sphcore.decomposition) and builds a Simulation (sphcore.stepper) of its share
alone: its particles and those of the others within the halo's width (share). They stay on its device; the grid
orders each cell's particles by id (id_order: ID_ORDER), so a sum over a cell runs in the same order whatever rows
a rank holds them in. A step:
  [1] the rows each other rank needs (picked at the end of the last step, [4]) and each rank's owned particles per
      cell layer (from the rows the last sort gave each layer), one Allgather of both: the particles' total checked,
      and the next cuts balanced on them (a rank's own and 0.4 of its halo's: decomposition.balance), each cut moved a
      layer at most (a step later than the counts: the cuts the pick took are this step's slabs);
  [2] to every other rank, of the owned rows of the cell layers near its slab (decomposition.bands), those now in
      its slab (migration: what a step reads of a particle) and those within the halo's width of it (halo: what a
      step reads of a neighbour, HALO), as pick_rows.comp packed them on the device, copied in one submission: on
      one host's NVIDIA GPUs from GPU to GPU (sphcore.peers: CUDA IPC), else through host memory, on one host the
      ranks' shared memory (Shared: on Vulkan each device copies into and out of it), else one Alltoallv of bytes
      (nothing pickled, nothing picked on the host);
  [3] the received ones written over the old halo's rows, in the submission of [4];
  [4] the plan's stages (on Vulkan in one submission; two where the exchange overlaps the step's end; with an
      adaptive dt the stages up to the dt in one more before them), then pick_rows for the next
      exchange: reduce_dt takes the rank's slab's rows alone, choose_dt at level LARGEST writes the largest |v|^2
      and |a|^2 as its first partial, and the largest over the ranks (Allreduce) goes there, so every rank's
      choose_dt takes the same dt, the minimum over the ranks. Where the exchange overlaps the step's end
      (Rank.overlap) the pick (each row as integrate will store it: integrate_row.glsl) and pack_rows come first,
      at a fixed dt after the forces on the rows the pick reads, with an adaptive dt after choose_dt; then, left
      running while the host exchanges those rows ([1]-[2] of the next step), the forces on the other rows and
      integrate, or integrate alone. Where the rows go from GPU to GPU, the next step's submissions queue behind
      that one (the parameter block copied on the device first: VulkanBackend.resize's `ahead`), so at a fixed dt
      the device runs step after step with no wait between.
Snapshots are ParaView's parallel files: each rank writes its owned particles as one .vtp piece, rank 0 the
.pvtp naming the pieces, listed in the .pvd. The checkpoint and final.npz are gathered on rank 0's host in
particle-id order, checked and written there as a 1-rank run writes them (no device holds more than its share);
a checkpoint resumes on any number of ranks (`sphcore run --resume`; Rank.restore). A gauge samples on every rank
what lies in its slab (sample_gauges.comp); rank 0 takes each sample from the rank that holds it (gauges.merged;
a force or moment: its sums over each cell layer, each from the rank that holds it, added along the layers) and
writes RUN/gauges/*.csv as one rank does. At a snapshot each rank checks its own particles, the energy summed over
the ranks (a failure more than a step after the last good check replayed from it, to name the first bad step).
SIGINT or SIGTERM on any rank stops every rank at one step, after a checkpoint.
Progress and messages come from rank 0. An error on any rank stops every rank (MPI Abort) after printing the
rank's message; a scene every rank refuses (check) is refused in one line by rank 0, and every rank exits.

N ranks give bitwise the state of a Simulation with id_order on one process (tests/test_parallel.py). A plain
Simulation orders a cell's particles by their previous index, not their id, so its sums run in another order: a
few ulps away at first, then as far apart as a flow lets two runs drift.
"""
import contextlib
import mmap
import os
import signal
import sys
import time
from pathlib import Path

import numpy as np

from sphcore import decomposition, folder, gauges, health
from sphcore.backends import packed
from sphcore.decomposition import SIZE_VARIABLES, launched_ranks  # noqa: F401 (sphcore.parallel's)
from sphcore.checkpoint import CARRIED, CHECKPOINT
from sphcore.errors import Interrupted, RefusedByRanks, SceneError, SimulationError
from sphcore.gauges import GaugeFiles
from sphcore.output import SnapshotSeries, vtp_bytes, write_vtp
from sphcore.peers import Peers
from sphcore.plan import PARTICLE_BUFFERS, PICK_ENTRIES, buffer_dtype, in_particle_order, row_bytes
from sphcore.runner import Schedule, _run_arguments, final_arrays
from sphcore.signals import Signals
from sphcore.stage import Stage
from sphcore.sph.dfsph import CONTROL_REBUILD
from sphcore.sph.pick_table import PICK_ALIGN
from sphcore.stepper import LOADED, SLAB_FIELDS, Simulation, wall_particles
from sphcore.vk_runner import Context

def world():
    """mpi4py's COMM_WORLD; SceneError naming the extra where mpi4py is missing. Open MPI 5's one-sided component
    osc/ucx, where UCX has no transport for one-sided calls (one host, TCP), prints a bogus "Error: OSC UCX component
    priority set inside component query failed" on every rank (open-mpi/ompi#14086): the one window here is in
    shared memory (osc/sm's), so osc/ucx is left out unless OMPI_MCA_osc names the components."""
    os.environ.setdefault("OMPI_MCA_osc", "^ucx")  # (read as MPI starts: the import below)
    try:
        from mpi4py import MPI
    except ImportError:
        raise SceneError("a run on several ranks needs mpi4py: pip install 'sphcore[mpi]'") from None
    return MPI.COMM_WORLD


def check(scene, backend):
    """Refuse (SceneError, one line) what this slice does not decompose yet, and an unknown SPHCORE_MPI_EXCHANGE."""
    refused = [("physics.pressure_solver", scene["physics.pressure_solver"] != "state_equation",
                "DFSPH (its solves iterate over all ranks' particles)"),
               ("domain.boundary", scene["domain.boundary"] != "walls", "an open domain (its grid wraps around)"),
               ("physics.neighbour_search", scene["physics.neighbour_search"] != "grid",
                "all-pairs search (the slabs are the grid's cell layers)")]
    for key, bad, what in refused:
        if bad:
            raise SceneError(f"{key}: a run on several ranks does not handle {what} yet; run on one rank")
    exchange = os.environ.get("SPHCORE_MPI_EXCHANGE", "")
    if exchange and exchange not in EXCHANGES:
        raise SceneError(f"SPHCORE_MPI_EXCHANGE={exchange}: choose one of {', '.join(EXCHANGES)} (or leave it unset: "
                         "cuda where every rank can, else host)")


def rank_device(local_rank):
    """The Vulkan device (its index) of the rank `local_rank` of a host: the local_rank-th, modulo their number,
    of the devices of the type Vulkan's default is (the GPUs where there are; else lavapipe)."""
    import vulkan as vk  # (only where Vulkan is used: sphcore.vk_runner imports it so too)

    with Context() as ctx:
        alike = [k for k, d in enumerate(vk.vkEnumeratePhysicalDevices(ctx.instance))
                 if ctx._type_name(vk.vkGetPhysicalDeviceProperties(d).deviceType) == ctx.device_type]
    return str(alike[local_rank % len(alike)])


def take(particles, mask):
    """The rows of `mask` of each array of `particles`."""
    return {name: values[mask] for name, values in particles.items()}


# What a rank sends rank 0 of its owned particles at a checkpoint (Rank.gather): every LOADED buffer, the ids first
# (rank 0 places each row at its id), in pieces of PIECE rows at most (an MPI count is 32-bit: 2^26 rows of 4
# components, 2^28 values).
SENT = ("particle_id", *(name for name in LOADED if name != "particle_id"))
PIECE = 1 << 26


class Stopped(Interrupted):
    """A signal stopped every rank at the same step, after a checkpoint (run): rank 0 says so, the others exit."""


# What a halo particle sends: what a step reads of a neighbour before writing it. compute_density and compute_forces
# read a neighbour's position, velocity, density (state with continuity) and id (the bodies' wall particles), and its
# pressure, which compute_density writes for every row first; a row's acceleration (compute_forces writes it, the
# sort's Verlet gather uses it as scratch) is read by that row's own stages only (integrate: a halo row's result is
# not kept). What a particle the receiver owns from now on (a migrant) sends: those, and Verlet's particle_vh (never
# written without Verlet: zero in every row); DFSPH's particle_kappa (zero without DFSPH, which a run on several
# ranks refuses: check) and the two a step writes before it reads them, particle_a and particle_p, stay.
# pick_rows.comp packs them into the sort's scratch buffers and scratch_vh (PACKED).
HALO = ("particle_x", "particle_v", "particle_rho", "particle_id")
PACKED = {"particle_x": "scratch_x", "particle_v": "scratch_v", "particle_rho": "scratch_rho",
          "particle_id": "scratch_id", "particle_vh": "scratch_vh"}


# The levels (Stage) of a step whose exchange overlaps its end (Rank.overlap): compute_forces' on the rows the pick
# reads, then on the others; pick_rows' before integrate, each row as integrate will store it.
PICKED_ROWS, OTHER_ROWS, BEFORE_INTEGRATE = 1, 2, 1
# choose_dt's level that writes the largest of a rank's partials as the first (Rank.reduce_dt)
LARGEST = 1
# After the sort, the rows the pick reads and their work groups (pick_groups.comp), for the stages of one invocation a
# row the pick reads or a row received, indirect dispatches (backends.RANK_GROUPS): compute_forces' first pass,
# pick_rows, pack_rows, place_rows
PICK_GROUPS = Stage("pick_groups")


def over_rows(name, level=0):
    """Stage `name` at `level`, of one invocation a row the pick reads or a row received (an indirect dispatch)."""
    return Stage(name, level, True)


PICK = [PICK_GROUPS, over_rows("pick_rows")]  # the pick after a step's stages, or alone


def write_groups(backend, row, invocations):
    """Row `row` of rank_groups: the work groups of `invocations` invocations, as pick_groups.comp writes row 0 (the
    host writes row 1, place_rows', with the rows received)."""
    backend.write_mapped("rank_groups", row, [-(-invocations // backend.local_size), 1, 1, invocations])


def sent_buffers(spec):
    """The buffers of the rows sent a rank: (those it owns from now on, those of its halo)."""
    return (HALO + ("particle_vh",) if spec.VERLET else HALO), HALO


# SPHCORE_MPI_EXCHANGE: the rows sent device to device (sphcore.peers), through the ranks' shared host memory
# (Shared), or in MPI messages (Rank.swap); unset: the first of these every rank can use.
EXCHANGES = ("cuda", "host", "alltoallv")
# The parts of a step Rank.seconds times: the exchange (its own parts after it: the counts' Allreduce, the rows read
# back, the Alltoallv or the shared memory's barrier, the rows written), the stages, the dt.
PARTS = ("exchange", "counts", "rows", "alltoall", "write", "stages", "dt")


class Slabs:
    """The slabs of a scene's grid (sphcore.decomposition, from the parameter block `params`): the axis, each
    particle's layer as the device's grid finds it, the halo's width and the layers it reaches past a cut."""

    def __init__(self, scene, params):
        P = params[0]
        self.axis = decomposition.slab_axis(scene.dim)
        self.box_min, self.inv_cell = float(P["box_min"][self.axis]), float(P["inv_cell"])
        self.cell_size = 1.0 / self.inv_cell
        self.layers = int(P["grid_dim"][self.axis])
        self.per_layer = int(np.prod(P["grid_dim"][:self.axis]))  # (cells.glsl: the layer is the slowest index)
        self.width = decomposition.halo_width(scene)
        self.summed = decomposition.summed_width(scene)
        self.reach = decomposition.reach_layers(self.width, self.inv_cell)

    def layers_of(self, x):
        return decomposition.layers_of(x, self.box_min, self.inv_cell, self.layers)

    def needed_by(self, x, owner, cuts, rank):
        return decomposition.needed_by(x, owner, cuts, self.box_min, self.cell_size, self.width, rank)


def share(scene, ranks, rank, precision=np.float32, x=None):
    """The start of rank `rank` of `ranks`: (cuts, keep), the cuts balanced over the scene's initial particles
    (the fluid's, then the bodies' wall particles: in id order) and the mask of those the rank holds (its own, its
    halo). Every rank computes the same from the scene's lattice (positions only, at the buffers' `precision`);
    each builds its Simulation of these alone (keep). `x`: the particles' positions in place of the lattice's (a
    checkpoint's: Rank.restore)."""
    if x is None:
        x = np.concatenate([scene.initial_positions(), wall_particles(scene)[0]]).astype(precision)
    slabs = Slabs(scene, scene.params(len(x)))
    coordinate = x[:, slabs.axis]
    layer = slabs.layers_of(coordinate)
    cuts = decomposition.balance(np.bincount(layer, minlength=slabs.layers), ranks, reach=slabs.reach)
    return cuts, slabs.needed_by(coordinate, decomposition.owners(layer, cuts), cuts, rank)


class Shared:
    """Memory the ranks of one host share (an MPI window, a part a rank), which each rank's device copies its rows
    for the others into and the others' for it out of directly (backend.host_buffer: on Vulkan the device's
    VK_EXT_external_memory_host, with no host copy and no message; numba copies its arrays). `make` gives one where
    every rank is on one host and every device takes the memory, else None (then the rows go by Alltoallv; also
    where SPHCORE_MPI_EXCHANGE=alltoallv)."""

    GRAIN = mmap.PAGESIZE  # a part's address and bytes are multiples of the page, in every process's mapping alike

    def __init__(self, comm, backend):
        self.comm, self.backend, self.window, self.capacity, self.buffers = comm, backend, None, 0, []

    @classmethod
    def make(cls, comm, backend):
        from mpi4py import MPI
        if os.environ.get("SPHCORE_MPI_EXCHANGE") == "alltoallv" or \
                comm.Split_type(MPI.COMM_TYPE_SHARED).Get_size() < comm.Get_size():
            return None
        shared = cls(comm, backend)
        return shared if shared.fit(1) else None

    def fit(self, nbytes):
        """Room for `nbytes` in each rank's part (collective: every rank asks for the same), grown by a quarter
        past it where there is less; whether every rank's device took every part (if not, none is kept)."""
        from mpi4py import MPI
        if nbytes <= self.capacity:
            return True
        self.close()
        self.capacity = -(-int(nbytes * 1.25) // self.GRAIN) * self.GRAIN
        info = MPI.Info.Create()
        info.Set("alloc_shared_noncontig", "true")
        self.window = MPI.Win.Allocate_shared(self.capacity + self.GRAIN, 1, info, comm=self.comm)
        info.Free()
        parts = [np.frombuffer(self.window.Shared_query(q)[0], np.uint8, self.capacity + self.GRAIN)
                 for q in range(self.comm.Get_size())]
        parts = [part[-part.ctypes.data % self.GRAIN:][:self.capacity] for part in parts]  # (Open MPI's start inside one)
        self.buffers = [self.backend.host_buffer(part) for part in parts]
        taken = np.array(all(b is not None for b in self.buffers))
        self.comm.Allreduce(MPI.IN_PLACE, taken, op=MPI.LAND)
        if not taken:
            self.close()
        return bool(taken)

    def close(self):
        """Free the parts (collective)."""
        for buffer in self.buffers:
            if buffer is not None and hasattr(buffer, "free"):  # (numba's are the arrays themselves)
                buffer.free()
        self.buffers = []
        if self.window is not None:
            self.window.Free()
        self.window, self.capacity = None, 0


class Rank:
    """One rank's share of a scene over MPI communicator `comm`, held by `sim` (a Simulation made with id_order and
    keep: share's): the particles of its slab (owned) and of the others' near it (the halo) on its device between
    steps, the cuts (at the start share's), and the step (module docstring). After a step, the rows the sort gave
    each cell layer (`starts`) say which are owned: the rows of the slab's layers."""

    def __init__(self, sim, comm, cuts):
        self.sim, self.comm, self.rank, self.size = sim, comm, comm.Get_rank(), comm.Get_size()
        names = [stage.name for stage in sim.stages]
        cut = names.index("reduce_dt") if "reduce_dt" in names else len(names)
        self.adaptive = cut < len(names)
        # (the dt over the ranks: choose_dt's largest of the rank's partials, the host's over the ranks, then the dt)
        self.before_dt = sim.stages[:cut + 1] + ([Stage("choose_dt", LARGEST)] if self.adaptive else [])
        self.after_dt = sim.stages[cut + 1:]
        # [4] the step's end in two submissions where it is the forces, the gauges, the dt and integrate, with no
        # shifting (whose sums are in the pick's scratch_v) and no reused lists: the pick (each row as integrate will
        # store it) and the pack, then the rest, left running while the exchange sends the picked rows (overlap). At
        # a fixed dt the first takes the forces on the rows the pick reads (band), the second the other rows' and the
        # rest (inside); with an adaptive dt the first takes choose_dt (after the forces and the dt over the ranks),
        # the second integrate alone
        spec, forces = sim.scene.spec, names.index("compute_forces") if "compute_forces" in names else len(names)
        self.overlap = (self.size > 1 and not spec.SHIFTING and not spec.LIST_SKIN and names[-1:] == ["integrate"]
                        and set(names[forces + 1:]) <= {"sample_gauges", "reduce_dt", "choose_dt", "integrate"})
        if self.adaptive:
            self.band, self.inside = self.after_dt[:-1] + [PICK_GROUPS], self.after_dt[-1:]
        else:
            self.band = sim.stages[:forces] + [PICK_GROUPS, over_rows("compute_forces", PICKED_ROWS)]
            self.inside = [Stage("compute_forces", OTHER_ROWS)] + sim.stages[forces + 1:]
        self.published = None  # (the outbox the step's pack wrote and published from: the exchange then packs none)
        self.seconds = dict.fromkeys(PARTS, 0.0)  # (a profile of step)
        self.slabs = Slabs(sim.scene, sim.params)
        self.axis, self.layers, self.per_layer, self.reach = (self.slabs.axis, self.slabs.layers,
                                                              self.slabs.per_layer, self.slabs.reach)
        precision = sim.scene["physics.precision"]
        self.row_bytes = {name: row_bytes(name, precision) for name in LOADED}
        self.sent = sent_buffers(sim.scene.spec)
        self.total = sim.scene.particle_count()
        self.cuts = np.asarray(cuts)
        self.next_cuts = self.cuts.copy()  # (the slabs of the step after the next: pick's)
        self.entries = self.picked = None  # (pick's table, and its counts after the step that picked)
        self.all_published = False  # (the exchange's: whether every rank published its rows at the step's end)
        self.start_owned = self.held_owned()  # (the start's snapshot)
        self.starts = None  # (no step yet: the held set is not sorted)
        exchange = os.environ.get("SPHCORE_MPI_EXCHANGE", "")
        self.peers = Peers.make(comm, sim.backend, exchange == "cuda") if exchange in ("", "cuda") else None
        self.shared = Shared.make(comm, sim.backend) if self.peers is None else None
        self.gauge_rows = []  # (rank 0: the gauges' samples read and not yet taken)
        self.good = None  # (what this rank held at the last step a check passed: keep, replay)
        sim.resize(sim.n, self.slab_fields())
        walls, body = wall_particles(sim.scene)  # (fixed: every rank knows them all, as health.check_bodies asks)
        sim.walls = {"particle_x": walls.astype(buffer_dtype("particle_x", precision)), "body": body}

    def restore(self, checkpoint):
        """Continue from `checkpoint` (load_checkpoint's arrays: of a run on any number of ranks, or one): the cuts
        balanced over its particles and this rank's share of them loaded (share, Simulation.restore), as at a
        start. The energy bound is the scene's initial state's, gathered first (gather)."""
        x = checkpoint["buffer_particle_x"]
        self.cuts, keep = share(self.sim.scene, self.size, self.rank, x=x[:, :self.sim.dim])
        self.next_cuts, self.picked = self.cuts.copy(), None
        self.sim.restore(checkpoint, keep, self.slab_fields())
        self.start_owned, self.starts = self.held_owned(), None
        self.keep()  # (the checkpoint's state, checked when it was written: a replay's start)

    def held_owned(self):
        """Of the particles this rank holds at a start, those of its slab (LOADED arrays)."""
        held = self.sim.backend.read(LOADED)
        owner = decomposition.owners(self.slabs.layers_of(held["particle_x"][:, self.axis]), self.cuts)
        return take(held, owner == self.rank)

    def slab_fields(self):
        """The cells of this rank's slab, those its particles can be in, and the coordinates of the rows whose density
        it sums (sphcore.stepper.SLAB_FIELDS): the slab's layers; the reach past each cut (the halo), a layer more (a
        particle owned at the last step: it moved a layer at most) and another (the cuts move a layer a step at most,
        so the cells counted at the last step are in the range now: the grid's cell stages leave every other cell
        empty); the slab widened by decomposition.summed_width (float32, as the parameter block holds them), open
        where the domain ends."""
        lo, hi = self.cuts[self.rank], self.cuts[self.rank + 1]
        first, end = max(lo - self.reach - 2, 0), min(hi + self.reach + 2, self.layers)
        bottom, top = (self.slabs.box_min + cut * self.slabs.cell_size for cut in (lo, hi))
        summed = (np.float32(bottom - self.slabs.summed if lo > 0 else -np.inf),
                  np.float32(top + self.slabs.summed if hi < self.layers else np.inf))
        return (*(layer * self.per_layer for layer in (lo, hi, first, end)), *summed)

    def owned_rows(self):
        """The rows of the particles this rank owns, after a step: those the sort put in its slab's layers."""
        return self.starts[self.cuts[self.rank]], self.starts[self.cuts[self.rank + 1]]

    def step(self):
        """One step of the decomposed run ([1]-[4] of the module docstring); the seconds of each part add up in
        `seconds`: exchange ([1]-[3]: the cuts, the rows read back, the Alltoallv, the new halo's copies listed),
        stages ([4], the new halo written first in the same submission, the pick of the rows the next step's
        exchange sends: none on one rank; where the exchange overlaps the step's end, the wait for the last step's
        second submission too), dt (the largest partial read and its Allreduce)."""
        from mpi4py import MPI
        if self.sim.gauges is not None:  # (the gauges' rings are read before a step could fill them)
            if self.sim.gauges.since >= self.sim.gauges.slots(self.layers).min():
                self.read_gauges()
            self.sim.gauges.since += 1
        start = time.perf_counter()
        writes, place = None, []
        if self.starts is None:  # (the first step: the pick's table of what is held)
            self.write_pick(self.sim.n)
        elif self.size > 1 or self.sim.scene.spec.LIST_SKIN:  # (one rank exchanges nothing, but with reused lists
            # its exchange's resize has them built every step, as on several ranks, whose rows change every step)
            writes, place = self.exchange()  # [1]-[3] (and the pick's table: write_pick)
        start = self.lap("exchange", start)
        backend, self.published = self.sim.backend, None
        pick = PICK if self.entries else []  # (none on one rank)
        stages = self.before_dt  # [4]
        if self.adaptive:  # (up to the dt, waited for, the last step's second too; then the dt over the ranks)
            backend.run_stages(place + self.before_dt, writes)
            start = self.lap("stages", start)
            self.reduce_dt(MPI)
            start = self.lap("dt", start)
            place, writes, stages = [], None, self.after_dt
        if self.overlap:
            outbox = self.peers.outbox if self.peers else None
            if outbox is not None:
                backend.bind_words("sent", outbox.buffer)
            pack = [over_rows("pack_rows")] if outbox is not None else []
            # both submissions queued behind the last step's second (ahead), waited for up to the first
            backend.run_stages(place + self.band + [over_rows("pick_rows", BEFORE_INTEGRATE)] + pack, writes, wait=False)
            backend.run_stages(self.inside, wait=False)  # (waited for in the next step, or as the device is read)
            backend.settle(keep=1)
        else:
            backend.run_stages(place + stages + pick, writes)
        self.starts = np.append(backend.read_mapped("layer_start", 0, self.layers), self.sim.n).astype(np.int64)
        self.picked = backend.read_mapped("pick_count", 0, 2 * len(self.entries))
        if self.overlap and outbox is not None:  # (the rows published while the second submission runs)
            nbytes = int(self.packed_bytes(self.picked.reshape(-1, 2).astype(np.int64)).sum())
            if nbytes <= outbox.nbytes and 2 * self.zones().sum() <= self.sim.n:
                self.peers.publish(nbytes)
                self.published = outbox
        self.lap("stages", start)
        self.sim.step_count += 1

    def read_gauges(self):
        """The gauges' new samples of every rank, merged on rank 0 as one rank takes them (gauges.merged) and kept
        there for take_gauge_rows (collective)."""
        samples = self.comm.gather(self.sim.gauges.samples(self.sim.backend, self.layers), root=0)
        if self.rank == 0:
            rows = self.sim.gauges.kept(gauges.merged(self.sim.scene, samples))
            self.gauge_rows = rows if not self.gauge_rows else [np.concatenate(p) for p in zip(self.gauge_rows, rows)]

    def take_gauge_rows(self):
        """Rank 0: the samples of each gauge since the last call (Simulation.take_gauge_rows' on one rank);
        collective."""
        self.read_gauges()
        rows, self.gauge_rows = self.gauge_rows, []
        return rows

    def lap(self, part, start):
        """Add the seconds since `start` to `part`'s; return now."""
        now = time.perf_counter()
        self.seconds[part] += now - start
        return now

    def reduce_dt(self, MPI):
        """The dt over every rank's owned particles: the largest |v|^2 and |a|^2 of reduce_dt's partials (of this
        rank's slab's rows alone), which choose_dt at level LARGEST wrote as the first partial, read (a buffer the
        host maps), the largest over the ranks (Allreduce; a maximum is exact in any order) written there: choose_dt
        then takes the world's dt on every rank."""
        backend = self.sim.backend
        largest = backend.read_mapped("dt_partial", 0, 1)[0]
        self.comm.Allreduce(MPI.IN_PLACE, largest, op=MPI.MAX)
        backend.write_mapped("dt_partial", 0, largest[None])

    def exchange(self):
        """[1]-[3] after a step: the rows of this rank's slab each other rank needs (pick: those picked at the end of
        the step, or picked now), and the owned particles per layer and those rows of every rank (one Allgather; the
        owned particles' total is checked: none lost, none twice); the rows copied from the device into the ranks'
        shared memory (swap_shared), from GPU to GPU (swap_peers) or sent in one Alltoallv (swap). The cuts the pick
        took become the slabs, and the next ones are balanced on the counts, each cut moved a layer at most. Returns
        the copies (write_parts' parts and move) and the stages (place_rows where the rows came from GPU to GPU:
        place) that write the received rows over the old halo, which the step's stages run after in one submission
        (the rows resized first). The owned rows stay where they are:
        one that another rank owns now stays a step, farther than the halo's width from every particle this rank
        owns (its halo rows are replaced at the next step); the sort puts every cell in id order whatever the rows
        (ID_ORDER). A halo row keeps the other buffers' values of whatever the row held."""
        r, starts, start = self.rank, self.starts, time.perf_counter()
        lo, hi = self.cuts[r], self.cuts[r + 1]
        first, end = self.owned_rows()
        regions, rows = self.pick()
        # (this rank's owned particles per layer, its rows, whether it published them at the step's end: swap_peers)
        mine = np.zeros(self.layers + 2 * self.size + 1, np.int64)
        mine[lo:hi] = np.diff(starts)[lo:hi]
        mine[self.layers:-1] = rows.reshape(-1)
        mine[-1] = self.published is not None
        every = np.empty((self.size, len(mine)), np.int64)
        self.comm.Allgather(mine, every)
        counts, self.all_published = every[:, :self.layers].sum(axis=0), every[:, -1].all()
        every = every[:, self.layers:-1].reshape(self.size, self.size, 2)
        if counts.sum() != self.total:
            raise SimulationError(f"step {self.sim.step_count}: the ranks own {counts.sum()} particles, not "
                                  f"{self.total}: a particle left the box, or crossed more than a cell layer in a step")
        start = self.lap("counts", start)
        # [2] the rows each other rank needs, copied and sent
        swap = self.swap_peers if self.peers else self.swap_shared if self.shared else self.swap
        received_rows, sources, start = swap(regions, every, start)
        # [3] the new halo in the rows of the old: below the owned rows, then after them (what the host decides first,
        # while the step's second submission may still run: overlap)
        m, owned = int(received_rows.sum()), end - first
        move = None
        if m < first:  # the owned rows' last ones fill the rows the new halo leaves free below them
            moved = min(first - m, owned)
            move = end - moved, m, moved
        self.cuts = self.next_cuts
        self.next_cuts = decomposition.balance(counts, self.size, previous=self.cuts, most=1, reach=self.reach)
        P, n, backend = self.sim.params[0], m + owned, self.sim.backend
        placed = self.peers and np.count_nonzero(received_rows.sum(axis=1)) <= PICK_ENTRIES
        self.write_pick(n)  # (the tables only the next step's first submission reads: written as the second runs)
        if placed:
            backend.write_mapped("place_table", 0, self.place_table(received_rows, sources, first, end))
            write_groups(backend, 1, int(received_rows.sum()))
            backend.bind_words("received", self.peers.inbox.buffer)
        start = self.lap("write", start)
        if not placed:  # (else the next step's submissions queue behind the second: ahead)
            backend.settle()
            waited, start = time.perf_counter() - start, time.perf_counter()
            self.seconds["stages"] += waited  # (the step's: step times the exchange as a whole, this wait out of it)
            self.seconds["exchange"] -= waited
        # a resize only where the count or the slab changed, or to have reused lists built (the rows moved and
        # written are listed by row: the buffers keep the rows past a smaller count)
        slab = self.slab_fields()
        if n != self.sim.n or tuple(P[list(SLAB_FIELDS)]) != slab or self.sim.scene.spec.LIST_SKIN:
            self.sim.resize(n, slab, ahead=placed)
        if placed:
            self.lap("write", start)
            return ([], move), [over_rows("place_rows")]
        at, parts = 0, {}  # (every rank's rows in one submission, with the move: its memory's regions)
        for q_rows, (data, offset) in zip(received_rows, sources):
            regions = parts.setdefault(id(data), (data, []))[1]
            for count, names in zip(q_rows, self.sent):
                for name in names:
                    below = min(max(first - at, 0), count)  # (rows of the halo below the owned ones; the rest after)
                    size = self.row_bytes[name]
                    regions += [(name, at, offset, below), (name, end + at + below - first, offset + below * size,
                                                            count - below)]
                    offset += packed(count * size)
                at += count
        self.lap("write", start)
        return (list(parts.values()), move), []

    @staticmethod
    def place_table(received_rows, sources, first, end):
        """The table of place_rows.comp, the step's first stage where the rows came from GPU to GPU: each sender's
        rows (ranks x 2: `received_rows`) in the inbox (`sources`: the inbox and the offset of each), which the
        device writes over the old halo's rows below the owned rows (`first` .. `end`), then after them."""
        table = np.zeros((1 + PICK_ENTRIES, 4), np.uint32)
        senders = [(offset, rows) for rows, (_, offset) in zip(received_rows, sources) if rows.sum()]
        table[0] = len(senders), first, end, received_rows.sum()
        for s, (offset, (migrants, halo)) in enumerate(senders):
            table[1 + s] = offset // 4, migrants, halo, 0
        return table

    def swap(self, regions, every, start):
        """Send each rank its rows: `regions` read back (rank by rank, `every`[s, q]: the rows of migrants and of halo
        rank s sends rank q), their bytes in one Alltoallv (byte counts are 32-bit, so under 2 GiB from one rank to
        another). Returns the rows received from each rank (ranks x 2), and for each rank where its bytes are (host
        memory, the offset there), and the time."""
        from mpi4py import MPI
        sent = self.sim.backend.read_regions(regions)
        start = self.lap("rows", start)
        received_rows = every[:, self.rank]
        send_bytes, receive_bytes = self.packed_bytes(every[self.rank]), self.packed_bytes(received_rows)
        received = self.sim.backend.space_to_write(int(receive_bytes.sum()))
        offsets = np.cumsum(receive_bytes) - receive_bytes
        self.comm.Alltoallv([sent, (send_bytes, np.cumsum(send_bytes) - send_bytes), MPI.BYTE],
                            [received, (receive_bytes, offsets), MPI.BYTE])
        return received_rows, [(received, int(offset)) for offset in offsets], self.lap("alltoall", start)

    def packed_bytes(self, rows):
        """The bytes of rows (..., 2: migrants, halo rows) as read_regions packs them (each buffer's run from a
        multiple of backends.PACK_GRAIN bytes), in pick's order."""
        return sum(packed(rows[..., k] * self.row_bytes[name]) for k, names in enumerate(self.sent) for name in names)

    def offsets(self, every):
        """Of `every` (the rows rank s sends rank q: ranks x ranks x 2), the bytes rank s sends rank q, and where those
        start among rank s's."""
        sizes = self.packed_bytes(every)
        return sizes, np.cumsum(sizes, axis=1) - sizes

    def swap_shared(self, regions, every, start):
        """swap's work through the ranks' shared memory (Shared): this rank's `regions` copied into its part, a
        barrier; each rank's bytes for this one are then in that rank's part."""
        sizes, offsets = self.offsets(every)
        if not self.shared.fit(int(sizes.sum(axis=1).max())):
            self.shared = None
            return self.swap(regions, every, start)
        self.sim.backend.read_regions(regions, into=self.shared.buffers[self.rank])
        start = self.lap("rows", start)
        self.comm.Barrier()  # (every part written; a part is written again after the next step's Allgather)
        return every[:, self.rank], [(self.shared.buffers[q], int(offsets[q, self.rank])) for q in range(self.size)], \
            self.lap("alltoall", start)

    def swap_peers(self, regions, every, start):
        """swap's work from device to device (sphcore.peers): this rank's rows packed into its outbox (pack: the
        bytes `regions` names, as read_regions would pack them) and published, unless the step did both (overlap),
        a barrier unless every rank's step did; then every rank's bytes for this one pulled into its inbox, and a
        barrier (no mailbox is written again before every rank has pulled from it)."""
        sizes, offsets = self.offsets(every)
        outbox = self.peers.outbox
        self.peers.fit(int(sizes.sum(axis=1).max()), int(sizes[:, self.rank].sum()))
        if self.published is not self.peers.outbox:  # (none published at the step's end, or from another outbox)
            self.pack()
            self.peers.publish(int(sizes[self.rank].sum()))
        start = self.lap("rows", start)
        if not self.all_published or self.peers.outbox is not outbox:  # (the same on every rank: fit is collective)
            self.comm.Barrier()  # (every rank's rows published)
        at = self.peers.pull([(q, int(offsets[q, self.rank]), int(sizes[q, self.rank])) for q in range(self.size)])
        self.comm.Barrier()  # (every mailbox pulled from: written again at the next step's end)
        return every[:, self.rank], [(self.peers.inbox.buffer, a) for a in at], self.lap("alltoall", start)

    @property
    def exchange_kind(self):
        """How the rows go: "cuda", "host" or "alltoallv" (EXCHANGES)."""
        return "cuda" if self.peers else "host" if self.shared else "alltoallv"

    def close(self):
        """Free the shared memory or the peers' boxes (collective: every rank, at the end of a run)."""
        if self.shared:
            self.shared.close()
        if self.peers:
            self.peers.close()

    def write_pick(self, n):
        """The table of the pick (pick_rows.comp) of a step of `n` rows held, written before it, the counts zeroed
        (into memory the host maps, backends.MAPPED: a submission left running reads none of it, band_rows): for
        each other rank, the layers of this rank's slab near its next slab (`next_cuts`; decomposition.bands), whose
        rows the step's sort gives (layer_start); of those, the ones then in its slab (its own from the next step on)
        and those within the halo's width of it. `entries`: each entry's rank and layers."""
        slabs, cuts = self.slabs, self.next_cuts
        entries = []
        for q in range(self.size):
            _, (below, above) = decomposition.bands(self.cuts, cuts, self.rank, q, self.reach)
            if q != self.rank and above[1] > below[0]:
                entries.append((q, below[0], above[1]))
        if len(entries) > PICK_ENTRIES:
            raise SimulationError(f"step {self.sim.step_count}: rank {self.rank} would send rows to {len(entries)} "
                                  f"ranks, more than {PICK_ENTRIES}: run on fewer ranks")
        table = np.zeros((1 + PICK_ENTRIES, 4), np.uint32)
        bounds = np.zeros((PICK_ENTRIES, 4), np.float32)
        table[0, :2] = len(entries), n
        for e, (q, first, end) in enumerate(entries):
            lo, hi = (slabs.box_min + cuts[k] * slabs.cell_size for k in (q, q + 1))
            table[1 + e] = first, end, cuts[q], cuts[q + 1]
            bounds[e, :2] = lo - slabs.width if q > 0 else -np.inf, hi + slabs.width if q < self.size - 1 else np.inf
        for name, values in (("pick_table", table), ("pick_bounds", bounds),
                             ("pick_count", np.zeros(2 * PICK_ENTRIES, np.uint32))):
            self.sim.backend.write_mapped(name, 0, values)
        self.entries = entries

    def pick(self):
        """The rows each other rank needs for the next step (write_pick), picked and packed on the device: by the
        last step's pick_rows, else now (after a replay), and again where their slots do not fit the rows (room
        made: a few rows held, or a slab thinner than the halo: rows several ranks need, each packed once for each).
        Returns the regions to read back (name, first row, end row) rank by rank, the migrants' then the halo's (as
        swap takes them), and the rows of each (ranks x 2)."""
        backend, picked = self.sim.backend, self.picked
        if picked is None:
            self.write_pick(self.sim.n)
        zones = self.zones()
        if self.entries and (picked is None or 2 * zones.sum() > self.sim.n):
            if 2 * zones.sum() > self.sim.n:  # (the table's rows held as they were)
                self.sim.resize(int(2 * zones.sum()), self.slab_fields())
                backend.write_rows("pick_count", 0, np.zeros(2 * PICK_ENTRIES, np.uint32))
            backend.run_stages(PICK)
            picked, self.published = backend.read_rows("pick_count", 0, 2 * len(self.entries)), None
        self.picked = None
        rows, regions = np.zeros((self.size, 2), np.int64), []
        counts = np.zeros((0, 2), np.int64) if picked is None else picked.reshape(-1, 2).astype(np.int64)
        for (q, _, _), base, zone, (migrants, halo) in zip(self.entries, 2 * (np.cumsum(zones) - zones), zones, counts):
            regions += [(PACKED[name], int(base), int(base + migrants)) for name in self.sent[0]]
            regions += [(PACKED[name], int(base + zone), int(base + zone + halo)) for name in self.sent[1]]
            rows[q] = migrants, halo
        return regions, rows

    def zones(self):
        """The slots of each of the pick's entries' two zones (pick_table.glsl), from the rows the step's sort gave
        their layers."""
        spans = np.array([self.starts[end] - self.starts[first] for _, first, end in self.entries], np.int64)
        return -(-spans // PICK_ALIGN) * PICK_ALIGN

    def pack(self):
        """pack_rows.comp, in a submission of its own: the rows the pick counted for each other rank written from the
        scratch buffers into the peers' outbox, as the step's last stage writes them where the exchange overlaps
        it."""
        self.sim.backend.bind_words("sent", self.peers.outbox.buffer)
        self.sim.backend.run_stages([over_rows("pack_rows")])

    def owned(self):
        """The particles this rank owns after a step (LOADED arrays, in the device's order), or at the start."""
        if self.starts is None:
            return self.start_owned
        first, end = self.owned_rows()
        return {name: self.sim.backend.read_rows(name, first, end) for name in LOADED}

    def write_piece(self, series, out_dir, step, t):
        """Each rank writes its owned particles (in the device's order) as its piece of snapshot `step`; rank 0
        (`series`, the others None) lists the pieces in the run folder's manifest first and, once all are written,
        names them in the snapshot's .pvtp, listed in the .pvd. The fluid's alone, as a 1-rank run's snapshots
        (the bodies' wall particles are in walls.vtp)."""
        dim, pieces, owned = self.sim.dim, None, self.owned()
        owned = take(owned, owned["particle_id"] < self.sim.fluid_count)
        x = owned["particle_x"][:, :dim]
        data = {"velocity": owned["particle_v"][:, :dim], "density": owned["particle_rho"],
                "pressure": owned["particle_p"]}
        if series is not None:
            pieces = series.piece_names(step, self.size)
            for name in pieces:
                series.folder.claim(name)
        pieces = self.comm.bcast(pieces, root=0)  # (claimed before any is written)
        write_vtp(Path(out_dir) / pieces[self.rank], x, data)
        self.comm.Barrier()  # (every piece written before the .pvtp names them)
        if series is not None:
            series.add_parallel(step, t, self.size, x, data)

    def gather(self):
        """Every rank's owned particles (LOADED) on rank 0's host, each row at its particle id, and every rank's grid
        status, checked there as read() checks a 1-rank run's (Simulation.checked; a failure as settle takes it);
        rank 0 keeps the arrays of the checkpoint and final.npz of that (`checkpoint`, `final`): those a 1-rank run
        writes, of every particle in id order. No device holds more than its share. A rank's rows cross as raw
        buffers (Send), a buffer at a time in pieces of PIECE rows (an MPI count is 32-bit), their ids first; the
        energy bound (the first gather's) goes to every rank."""
        sim, owned, failure = self.sim, self.owned(), None
        statuses = self.comm.gather(sim.backend.read_buffer("grid_status"), root=0)
        counts = self.comm.gather(len(owned["particle_id"]), root=0)
        if self.rank == 0:
            failure = self.assemble(owned, statuses, counts)
        else:
            for name in SENT:
                for k in range(0, len(owned[name]), PIECE):
                    self.comm.Send(owned[name][k:k + PIECE], dest=0)
        self.settle(failure, [0] if self.comm.bcast(failure is not None, root=0) else [])
        sim.energy_start = self.comm.bcast(sim.energy_start, root=0)
        sim.checked_step = sim.step_count

    def assemble(self, owned, statuses, counts):
        """Rank 0's part of gather: its own particles `owned` and every other rank's (`counts` of them, received),
        each buffer's rows placed at their ids (every id once: checked), read as a 1-rank run reads them. Returns
        the SimulationError of that read where it fails, else None."""
        sim = self.sim
        if sum(counts) != self.total:
            raise SimulationError(f"step {sim.step_count}: the ranks own {sum(counts)} particles, not {self.total}")
        whole = {name: np.empty((self.total, *values.shape[1:]), values.dtype) for name, values in owned.items()}
        seen = np.zeros(self.total, bool)  # (as many rows as particles, each id seen: each once)
        for r, count in enumerate(counts):
            ids = None
            for name in SENT:
                values = owned[name] if r == 0 else self.received(whole[name], count, r)
                if ids is None:
                    ids = values.astype(np.int64)
                    if (ids >= self.total).any():
                        raise SimulationError(f"step {sim.step_count}: rank {r} holds particle id {ids.max()}, past "
                                              f"the scene's {self.total} particles")
                    seen[ids] = True
                whole[name][ids] = values
        if not seen.all():
            raise SimulationError(f"step {sim.step_count}: particle {int(np.argmin(seen))} is owned by no rank (another "
                                  "is owned twice)")
        state = {name: values[:, :sim.dim] if values.ndim == 2 else values for name, values in whole.items()}
        try:
            state = sim.checked(state, statuses)
        except SimulationError as failure:
            return failure
        carried = sim.backend.read([name for name in CARRIED if name not in LOADED])
        carried["control"][CONTROL_REBUILD] = 1  # (a rank's next step builds its lists: every step does)
        carried = {name: whole[name] if name in whole else carried[name] for name in CARRIED}
        params = sim.params_of(self.total)  # (every particle owned: a 1-rank run's)
        self.checkpoint, self.final = sim.checkpoint_of(carried, params), final_arrays(sim, state, params)
        return None

    def received(self, like, count, source):
        """`count` rows of a buffer (`like`'s dtype and row shape) that rank `source` sends (gather)."""
        rows = np.empty((count, *like.shape[1:]), like.dtype)
        for k in range(0, count, PIECE):
            self.comm.Recv(rows[k:k + PIECE], source=source)
        return rows

    def check(self, replay=True):
        """Check the particles this rank owns, without gathering them, as read() checks a 1-rank run's
        (sphcore.health): every per-particle buffer's owned rows, in id order (a message names a particle by its
        id), this rank's grid status, and the energy bound with the energy summed over the ranks (in rank order)
        and the fastest particle the fastest of theirs (allgather of health.energy_figures). A failure on any
        rank as settle takes it (`replay`: from the last good step)."""
        sim, backend = self.sim, self.sim.backend
        first, end = self.owned_rows()
        state = in_particle_order({name: backend.read_rows(name, first, end) for name in PARTICLE_BUFFERS}, sim.dim)
        state = take(state, state["particle_id"] < sim.fluid_count)  # (the fluid's: a 1-rank read checks those)
        ids = state["particle_id"]
        figures = self.comm.allgather(health.energy_figures(sim.scene, state, ids))
        world = (sum(f[0] for f in figures), *max(figures, key=lambda f: (f[1], -f[2]))[1:])
        failure = None
        try:
            health.check_state(sim, state, ids, world)
            health.check_grid(sim, backend.read_buffer("grid_status"))
        except SimulationError as e:
            failure = e
        self.settle(failure, [r for r, found in enumerate(self.comm.allgather(failure is not None)) if found], replay)
        sim.checked_step = sim.step_count

    def settle(self, failure, failed, replay=True):
        """After a check on every rank (collective): `failed` the ranks whose check failed (`failure` this rank's).
        None: this rank keeps its state (keep). Else, more than a step past the last good state and with `replay`,
        every rank replays from it (replay: the check of the first step that fails raises, as a 1-rank run's names
        that step); then the first rank that failed raises its failure, which main prints before it aborts every
        rank, and the others wait for that."""
        if not failed:
            if replay:
                self.keep()
            return
        if replay and self.good is not None and self.sim.step_count - self.good[-1] > 1:
            self.replay()
        if failed[0] == self.rank:
            raise failure
        self.comm.Barrier()  # (not passed: rank failed[0] aborts every rank)

    def keep(self):
        """Keep what this rank holds at a step a check passed, for replay: every CARRIED buffer of its rows, its
        cuts and the rows of each layer."""
        self.good = self.sim.backend.read(CARRIED), self.cuts.copy(), self.next_cuts.copy(), self.starts, \
            self.sim.step_count

    def replay(self):
        """Every rank back where its last good check left it (keep: its rows loaded again, the cuts, the step), then
        a step at a time, each checked, up to the step whose check failed: the first that fails raises. The steps
        are the same bits as the first time (any cuts give one rank's)."""
        failed_at, (carried, self.cuts, self.next_cuts, self.starts, step) = self.sim.step_count, self.good
        self.sim.load({name: carried[name] for name in LOADED}, self.slab_fields())
        for name in CARRIED:
            if name not in LOADED:
                self.sim.backend.write_buffer(name, carried[name])
        self.picked = None  # (the scratch rows are of a later step: picked again, from the rows of each layer)
        if self.starts is not None:
            self.sim.backend.write_rows("layer_start", 0, self.starts[:-1].astype(np.uint32))
        self.sim.step_count = self.sim.checked_step = step
        while self.sim.step_count < failed_at:
            self.step()
            self.check(replay=False)

    def stopped(self, signals):
        """The first signal any rank received (sphcore.signals.Signals: `signals`), or 0: every rank stops at the
        same step."""
        from mpi4py import MPI
        return self.comm.allreduce(signals.received or 0, op=MPI.MAX)


def run(scene, steps=None, out_dir=None, progress=True, overwrite=False, comm=None, backend="numba",
        local_size=128, device=None, checkpoint=None):
    """Run `scene` decomposed over the ranks of `comm` (default: MPI's world), as sphcore.run does on one: snapshots
    every time.output_every steps (or time.output_interval), a .vtp piece a rank and their .pvtp (write_piece), each
    rank's particles checked first (Rank.check); a checkpoint at the start, every time.checkpoint_every steps, at
    the end and where SIGINT or SIGTERM stops the run (on any rank: every rank stops at that step, Stopped), and
    final.npz, gathered on rank 0's host in particle-id order, checked there and written into `out_dir`. With
    `checkpoint` (load_checkpoint's arrays of the run in `out_dir`, written on any number of ranks) the run
    continues from it (Rank.restore), its particles' arrays dropped from the mapping once loaded (each rank keeps
    its share alone); one rank continues it as well (sphcore.resume). Return the final arrays on rank 0, None on
    the others. On Vulkan each rank runs on `device` (an index or part of a name), by default its host's rank-th
    GPU (rank_device)."""
    comm = comm or world()
    refused = None
    try:
        check(scene, backend)
    except SceneError as e:
        refused = str(e)
    refused = comm.allgather(refused)  # (the same on every rank but where the environment differs)
    if any(refused):
        first = next(r for r, why in enumerate(refused) if why)
        same = all(why == refused[first] for why in refused)
        raise RefusedByRanks(refused[first] if same else f"rank {first} of {comm.Get_size()}: {refused[first]}")
    options = {"local_size": local_size}
    if backend == "vulkan":
        from mpi4py import MPI
        options["device"] = device if device is not None else rank_device(
            comm.Split_type(MPI.COMM_TYPE_SHARED).Get_rank())
    scene, steps, out_dir = _run_arguments(scene, backend, steps, out_dir, progress, checkpoint, overwrite, options)
    root = comm.Get_rank() == 0
    schedule = Schedule(scene, steps)
    with Signals() as signals, folder.RunFolder(out_dir) if root else contextlib.nullcontext() as run_folder:
        if root:  # (rank 0 writes)
            folder.remove_stale_temporaries(out_dir)
            run_folder.prepare(scene["name"], resume=checkpoint is not None, overwrite=overwrite)
            if checkpoint is None:
                run_folder.write_bytes("scene.json", scene.to_json().encode())
            series = SnapshotSeries(out_dir, scene["name"], folder=run_folder)
            if checkpoint is not None:
                series.truncate(int(checkpoint["step"]))  # (snapshots past the checkpoint: of steps to run again)
        cuts, keep = share(scene, comm.Get_size(), comm.Get_rank(), buffer_dtype("particle_x", scene["physics.precision"]))
        with Simulation(scene, backend, id_order=True, keep=keep, poll=signals.poll, **options) as sim:
            rank = Rank(sim, comm, cuts)
            if root and scene["bodies"] and checkpoint is None:  # the bodies' wall particles: fixed, written once
                run_folder.write_bytes("walls.vtp", vtp_bytes(sim.walls["particle_x"], {"body": sim.walls["body"]}))
            if root and progress:
                how = {"cuda": "from GPU to GPU (CUDA IPC)", "host": "through shared memory",
                       "alltoallv": "through MPI messages (Alltoallv)"}[rank.exchange_kind]
                print(f"{scene['name']}: {rank.size} ranks, the halo {how}", flush=True)

            resumed, taken = None, None
            if checkpoint is not None:
                rank.gather()  # (the initial state's energy: the bound, checked against the checkpoint's)
                rank.restore(checkpoint)
                for name in LOADED:
                    del checkpoint[f"buffer_{name}"]
                resumed = int(checkpoint["step"])
                taken = checkpoint["gauge_state"][1::2, 1] if "gauge_state" in checkpoint else None
            files = GaugeFiles(run_folder, scene, taken) if root and sim.gauges is not None else None

            def write_gauges():  # (every rank: the samples gathered; before a checkpoint, which counts them)
                if sim.gauges is not None:
                    rows = rank.take_gauge_rows()
                    if files is not None:
                        files.add(rows)
                        files.write()

            def save_checkpoint():  # (every rank: the gather)
                write_gauges()
                rank.gather()  # (the start's: its energy the bound of the later checks)
                if root:
                    run_folder.savez(CHECKPOINT, **rank.checkpoint)

            def snapshot():
                rank.write_piece(series if root else None, out_dir, sim.step_count, sim.time)

            if checkpoint is None:
                save_checkpoint()
                snapshot()
            signals.stepping = True
            stopped, t = 0, schedule.time(sim)
            with schedule.progress(sim, t, disable=not (progress and root),
                                   desc=f"{scene['name']} [{backend} x {rank.size} ranks]") as bar:
                while not schedule.done(sim, t) and not stopped:
                    rank.step()
                    before, t = t, schedule.time(sim)
                    bar.update(1 if schedule.end_time is None else min(t, schedule.end_time) - before)
                    stopped = rank.stopped(signals)
                    due = schedule.checkpoint_due(sim) or schedule.done(sim, t) or stopped
                    if due or schedule.snapshot_due(sim, before, t):
                        write_gauges()
                    if due:
                        rank.gather()  # (checked there)
                    if schedule.snapshot_due(sim, before, t):
                        if not due:
                            rank.check()
                        snapshot()
                    if due and root:
                        run_folder.savez(CHECKPOINT, **rank.checkpoint)
            if sim.step_count == resumed:
                rank.gather()  # (resumed and no step to run: the final arrays of the checkpoint's state)
            rank.close()
            if stopped and not schedule.done(sim, t):
                raise Stopped(stopped, f"interrupted by {signal.Signals(stopped).name} at step {sim.step_count} "
                              f"{schedule.of(sim)} on {rank.size} ranks; checkpoint written: continue with "
                              f"`sphcore run --resume {out_dir}` (on any number of ranks)")
            if not root:
                return None
            run_folder.savez("final.npz", **rank.final)
            return rank.final


def main(run_args):
    """`sphcore run` under mpiexec: run_args (scene, steps, out, overwrite, local_size, backend, device) on every
    rank; an error on a rank prints `rank R: message` and aborts every rank. A scene every rank refuses
    (RefusedByRanks) and a signal, which stops every rank at one step (Stopped): rank 0 says so, the others exit
    with the same status."""
    comm = world()
    try:
        return run(**run_args, comm=comm)
    except RefusedByRanks:
        if comm.Get_rank() == 0 or comm.Get_size() == 1:
            raise
        sys.exit(1)
    except Stopped as e:
        if comm.Get_rank() == 0 or comm.Get_size() == 1:
            raise
        sys.exit(128 + e.signum)
    except BaseException as e:
        # one write: print() writes the line and its newline apart, and mpiexec's abort banner can land between
        sys.stderr.write(f"sphcore: error: rank {comm.Get_rank()} of {comm.Get_size()}: {e}\n")
        sys.stderr.flush()
        if comm.Get_size() > 1:
            comm.Abort(1)
        raise
