"""One scene on N MPI ranks (issue 34; docs/parallel.md): `mpiexec -n N sphcore run SCENE`, or
`sphcore.parallel.run` under mpiexec, on the numba or the Vulkan backend (rank r of a host on its r-th GPU).

Each rank owns a slab of the domain (sphcore.decomposition) and builds a Simulation (sphcore.stepper) of its share
alone: its particles and those of the others within the halo's width (share). They stay on its device; the grid
orders each cell's particles by id (id_order: ID_ORDER), so a sum over a cell runs in the same order whatever rows
a rank holds them in. A step:
  [1] the cuts: each rank's owned particles per cell layer (from the rows the last sort gave each layer), summed
      over the ranks (Allreduce, their total checked) and balanced, each cut moved a layer at most;
  [2] the owned rows near a cut read back (positions first); to every other rank those it owns now (migration:
      every buffer of a particle) or must see (halo: the buffers a step reads of a neighbour, HALO), through host
      memory (mpi4py's Alltoallv of records: nothing pickled);
  [3] the received ones written over the old halo's rows;
  [4] the plan's stages (on Vulkan in two submissions): reduce_dt takes the rank's slab's rows alone, and the
      largest |v|^2 and |a|^2 over the ranks (Allreduce) go into its first partial, so every rank's choose_dt
      takes the same dt, the minimum over the ranks.
Snapshots are ParaView's parallel files: each rank writes its owned particles as one .vtp piece, rank 0 the
.pvtp naming the pieces, listed in the .pvd. The checkpoint and final.npz are gathered on rank 0's host in
particle-id order, checked and written there as a 1-rank run writes them (no device holds more than its share);
a checkpoint resumes on one rank (`sphcore run --resume`). At a snapshot each rank checks its own particles, the
energy summed over the ranks. SIGINT or SIGTERM on any rank stops every rank at one step, after a checkpoint.
Progress and messages come from rank 0. An error on any rank stops every rank (MPI Abort) after printing the
rank's message.

N ranks give bitwise the state of a Simulation with id_order on one process (tests/test_parallel.py). A plain
Simulation orders a cell's particles by their previous index, not their id, so its sums run in another order: a
few ulps away at first, then as far apart as a flow lets two runs drift.
"""
import contextlib
import signal
import sys
import time
from pathlib import Path

import numpy as np

from sphcore import decomposition, folder, health
from sphcore.decomposition import SIZE_VARIABLES, launched_ranks  # noqa: F401 (sphcore.parallel's)
from sphcore.checkpoint import CARRIED, CHECKPOINT
from sphcore.errors import Interrupted, SceneError, SimulationError
from sphcore.output import SnapshotSeries, write_vtp
from sphcore.plan import BUFFERS, PARTICLE_BUFFERS, buffer_dtype, in_particle_order
from sphcore.runner import Schedule, _run_arguments, final_arrays
from sphcore.signals import Signals
from sphcore.sph.dfsph import CONTROL_REBUILD
from sphcore.stepper import LOADED, Simulation
from sphcore.vk_runner import Context

def world():
    """mpi4py's COMM_WORLD; SceneError naming the extra where mpi4py is missing."""
    try:
        from mpi4py import MPI
    except ImportError:
        raise SceneError("a run on several ranks needs mpi4py: pip install 'sphcore[mpi]'") from None
    return MPI.COMM_WORLD


def check(scene, backend):
    """Refuse (SceneError, one line) what this slice does not decompose yet."""
    refused = [("physics.pressure_solver", scene["physics.pressure_solver"] != "state_equation",
                "DFSPH (its solves iterate over all ranks' particles)"),
               ("bodies", bool(scene["bodies"]), "bodies (their wall pressure reads a third neighbour level)"),
               ("gauges", bool(scene.config.get("gauges")), "gauges (their samples sum over every rank)"),
               ("domain.boundary", scene["domain.boundary"] != "walls", "an open domain (its grid wraps around)")]
    for key, bad, what in refused:
        if bad:
            raise SceneError(f"{key}: a run on several ranks does not handle {what} yet; run on one rank")


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


# What a halo particle sends (a migrant, one the receiver owns now, sends every LOADED buffer): what a step reads
# of a neighbour before writing it. compute_density and compute_forces read a neighbour's position, velocity,
# density (state with continuity) and id (the bodies' wall particles), and its pressure, which compute_density
# writes for every row first; a row's acceleration (compute_forces writes it), Verlet's particle_vh and DFSPH's
# particle_kappa are read by that row's own stages only (integrate: a halo row's result is not kept).
HALO = ("particle_x", "particle_v", "particle_rho", "particle_id")

# The parts of a step Rank.seconds times: the exchange (its own parts after it: the counts' Allreduce, the edges'
# positions read back and the halo picked, its rows read back, the Alltoall(v)s, the rows written), the stages, the dt.
PARTS = ("exchange", "counts", "edges", "rows", "alltoall", "write", "stages", "dt")


class Slabs:
    """The slabs of a scene's grid (sphcore.decomposition, from the parameter block `params`): the axis, each
    particle's layer as the device's grid finds it, the halo's width and the edges' depth."""

    def __init__(self, scene, params):
        P = params[0]
        self.axis = decomposition.slab_axis(scene.dim)
        self.box_min, self.inv_cell = float(P["box_min"][self.axis]), float(P["inv_cell"])
        self.cell_size = 1.0 / self.inv_cell
        self.layers = int(P["grid_dim"][self.axis])
        self.per_layer = int(np.prod(P["grid_dim"][:self.axis]))  # (cells.glsl: the layer is the slowest index)
        self.width = decomposition.halo_width(scene)
        self.edge = decomposition.edge_layers(self.width, self.inv_cell)

    def layers_of(self, x):
        return decomposition.layers_of(x, self.box_min, self.inv_cell, self.layers)

    def needed_by(self, x, owner, cuts, rank):
        return decomposition.needed_by(x, owner, cuts, self.box_min, self.cell_size, self.width, rank)


def share(scene, ranks, rank, precision=np.float32):
    """The start of rank `rank` of `ranks`: (cuts, keep), the cuts balanced over the scene's initial particles and
    the mask of those the rank holds (its own, its halo). Every rank computes the same from the scene's lattice
    (positions only, at the buffers' `precision`); each builds its Simulation of these alone (keep)."""
    x = scene.initial_positions().astype(precision)
    slabs = Slabs(scene, scene.params(len(x)))
    coordinate = x[:, slabs.axis]
    layer = slabs.layers_of(coordinate)
    cuts = decomposition.balance(np.bincount(layer, minlength=slabs.layers), ranks)
    return cuts, slabs.needed_by(coordinate, decomposition.owners(layer, cuts), cuts, rank)


class Rank:
    """One rank's share of a scene over MPI communicator `comm`, held by `sim` (a Simulation made with id_order and
    keep: share's): the particles of its slab (owned) and of the others' near it (the halo) on its device between
    steps, the cuts (at the start share's), and the step (module docstring). After a step, the rows the sort gave
    each cell layer (`starts`) say which are owned: the rows of the slab's layers."""

    def __init__(self, sim, comm, cuts):
        self.sim, self.comm, self.rank, self.size = sim, comm, comm.Get_rank(), comm.Get_size()
        names = [stage.name for stage in sim.stages]
        cut = names.index("reduce_dt") if "reduce_dt" in names else len(names)
        self.before_dt, self.after_dt = sim.stages[:cut + 1], sim.stages[cut + 1:]  # (the dt: over the ranks)
        self.adaptive = cut < len(names)
        self.seconds = dict.fromkeys(PARTS, 0.0)  # (a profile of step)
        self.slabs = Slabs(sim.scene, sim.params)
        self.axis, self.layers, self.per_layer, self.edge = (self.slabs.axis, self.slabs.layers,
                                                             self.slabs.per_layer, self.slabs.edge)
        self.total = sim.scene.particle_count()
        self.cuts = np.asarray(cuts)
        held = sim.backend.read(LOADED)
        owner = decomposition.owners(self.slabs.layers_of(held["particle_x"][:, self.axis]), self.cuts)
        self.start_owned = take(held, owner == self.rank)  # (the start's snapshot)
        self.starts = None  # (no step yet: the held set is not sorted)
        sim.resize(sim.n, self.owned_cells())

    def owned_cells(self):
        """The cells of this rank's slab (params.glsl: owned_first, owned_end)."""
        return self.cuts[self.rank] * self.per_layer, self.cuts[self.rank + 1] * self.per_layer

    def owned_rows(self):
        """The rows of the particles this rank owns, after a step: those the sort put in its slab's layers."""
        return self.starts[self.cuts[self.rank]], self.starts[self.cuts[self.rank + 1]]

    def step(self):
        """One step of the decomposed run ([1]-[4] of the module docstring); the seconds of each part add up in
        `seconds`: exchange ([1]-[3]: the cuts, the edges read back, the Alltoallv, the rows written), stages
        ([4]), dt (the partials read back and their Allreduce)."""
        from mpi4py import MPI
        start = time.perf_counter()
        if self.starts is not None:
            self.exchange()  # [1]-[3]
        start = self.lap("exchange", start)
        backend = self.sim.backend
        backend.run_stages(self.before_dt)  # [4]
        start = self.lap("stages", start)
        if self.adaptive:
            self.reduce_dt(MPI)
            start = self.lap("dt", start)
        backend.run_stages(self.after_dt)
        rows = np.arange(self.layers) * self.per_layer
        self.starts = np.append(backend.read_entries("cell_start", rows), self.sim.n).astype(np.int64)
        self.lap("stages", start)
        self.sim.step_count += 1

    def lap(self, part, start):
        """Add the seconds since `start` to `part`'s; return now."""
        now = time.perf_counter()
        self.seconds[part] += now - start
        return now

    def reduce_dt(self, MPI):
        """The dt over every rank's owned particles: reduce_dt's partials (of this rank's slab's rows alone) read
        back, their largest |v|^2 and |a|^2 (a maximum is exact in any order) the largest over the ranks
        (Allreduce), written as the first partial: choose_dt then takes the world's dt on every rank."""
        backend = self.sim.backend
        groups = -(-self.sim.n // backend.local_size)
        partials = backend.read_rows("dt_partial", 0, groups)
        largest = partials.max(axis=0) if groups else np.zeros(2, partials.dtype)
        self.comm.Allreduce(MPI.IN_PLACE, largest, op=MPI.MAX)
        backend.write_rows("dt_partial", 0, largest[None])

    def exchange(self):
        """[1]-[3] after a step: the owned particles per layer summed over the ranks (Allreduce; their total is
        checked: none lost, none twice) and the new cuts, each moved a layer at most; the positions of the owned
        rows within `edge` layers of a cut read back, and of those the rows each other rank owns now (migrants:
        every LOADED buffer's row) or needs as halo (the HALO buffers' rows) sent to it (Alltoallv, sent); the
        received ones replace the old halo, the migrants first. The owned rows stay where they are: one that
        another rank owns now and this one no longer sees stays a step, farther than the halo's width from every
        particle this rank owns (its halo rows are replaced at the next step); the sort puts every cell in id
        order whatever the rows (ID_ORDER). A halo row keeps the other buffers' values of whatever the row held."""
        from mpi4py import MPI
        r, backend, starts, start = self.rank, self.sim.backend, self.starts, time.perf_counter()
        lo, hi = self.cuts[r], self.cuts[r + 1]
        first, end = self.owned_rows()
        counts = np.zeros(self.layers, np.int64)
        counts[lo:hi] = np.diff(starts)[lo:hi]
        self.comm.Allreduce(MPI.IN_PLACE, counts, op=MPI.SUM)
        if counts.sum() != self.total:
            raise SimulationError(f"step {self.sim.step_count}: the ranks own {counts.sum()} particles, not "
                                  f"{self.total}: a particle left the box, or crossed more than a cell layer in a step")
        cuts = decomposition.balance(counts, self.size, previous=self.cuts, most=1)
        start = self.lap("counts", start)
        # [2] the edges: the owned rows first .. a - 1 and b .. end - 1 (none below the first slab, above the last),
        # their positions read back; the rows of each edge each other rank owns now (migrants) or needs as halo
        a = starts[min(lo + self.edge, hi)] if r > 0 else first
        b = max(a, starts[max(hi - self.edge, lo)] if r < self.size - 1 else end)
        edges = [(s, e, backend.read_rows("particle_x", s, e)) for s, e in ((first, a), (b, end)) if e > s]
        migrants, halo = [[] for _ in range(self.size)], [[] for _ in range(self.size)]
        for s, _, x in edges:
            z = x[:, self.axis]
            owner = decomposition.owners(self.slabs.layers_of(z), cuts)
            for q in self.reached(z, cuts):
                migrants[q].append(s + np.flatnonzero(owner == q))
                halo[q].append(s + np.flatnonzero(self.slabs.needed_by(z, owner, cuts, q) & (owner != q)))
        start = self.lap("edges", start)
        full, lean = self.packed(edges, migrants, LOADED), self.packed(edges, halo, HALO)
        start = self.lap("rows", start)
        full, lean = self.swapped([(full, migrants), (lean, halo)])
        start = self.lap("alltoall", start)
        # [3] the new halo in the rows of the old: below the owned rows, then after them; the migrants first
        m, owned = len(full) + len(lean), end - first
        if m < first:  # the owned rows' last ones fill the rows the new halo leaves free below them
            moved = min(first - m, owned)
            backend.move_rows(end - moved, m, moved)
        self.cuts = cuts
        self.sim.resize(m + owned, self.owned_cells())
        for at, records in ((0, full), (len(full), lean)):
            for name in records.dtype.names:
                self.write_halo(name, at, records[name], first, end)
        self.lap("write", start)

    def reached(self, z, cuts):
        """The other ranks whose band (their slab and the halo's width either side: needed_by) meets the
        coordinates `z` of some edge's rows, under `cuts`: the others own none of them and need none."""
        low, high = float(z.min()), float(z.max())
        slabs = self.slabs
        bounds = slabs.box_min + np.asarray(cuts, np.float64) * slabs.cell_size
        return [q for q in range(self.size) if q != self.rank
                and (q == 0 or high >= bounds[q] - slabs.width)
                and (q == self.size - 1 or low < bounds[q + 1] + slabs.width)]

    def packed(self, edges, picked, names):
        """The rows `picked` (per rank, a list of arrays of row numbers of the edges) of buffers `names` as one record
        array, rank by rank: each buffer read back once over the span of the picked rows of each edge (the edge's
        positions, `edges`' third item, as they are)."""
        rows = np.concatenate([np.zeros(0, np.int64), *(run for runs in picked for run in runs)])
        records = np.empty(len(rows), self.record(names))
        for s, e, x in edges:
            inside = (rows >= s) & (rows < e)
            if not inside.any():
                continue
            at = rows[inside]
            u, w = at.min(), at.max() + 1
            for name in names:
                values = x[u - s:w - s] if name == "particle_x" else self.sim.backend.read_rows(name, u, w)
                records[name][inside] = values[at - u]
        return records

    def record(self, names):
        """The numpy record of a row of buffers `names` (their dtypes at the scene's precision)."""
        precision = self.sim.scene["physics.precision"]
        return np.dtype([(name, buffer_dtype(name, precision), (BUFFERS[name][1],) if BUFFERS[name][1] > 1 else ())
                         for name in names])

    def swapped(self, groups):
        """The records every rank sends this one, of each of `groups` sent, (records, picked): rank q's records, as
        many as `picked` has rows for it, one rank's after the other's. Their counts first (one Alltoall), then
        each group's bytes (Alltoallv: byte counts are 32-bit, so under 2 GiB from one rank to another)."""
        from mpi4py import MPI
        sent = np.array([[sum(map(len, picked[q])) for _, picked in groups] for q in range(self.size)], np.int64)
        received = np.empty_like(sent)
        self.comm.Alltoall(sent, received)
        swapped = []
        for k, (records, _) in enumerate(groups):
            into = np.empty(received[:, k].sum(), records.dtype)
            self.comm.Alltoallv(self.message(records, sent[:, k], MPI), self.message(into, received[:, k], MPI))
            swapped.append(into)
        return swapped

    @staticmethod
    def message(records, counts, MPI):
        """An Alltoallv's buffer of `records`, `counts` of them for each rank in rank order, as bytes."""
        counts = counts * records.dtype.itemsize
        return [records.view(np.uint8), (counts, np.cumsum(counts) - counts), MPI.BYTE]

    def write_halo(self, name, at, values, first, end):
        """Write `values` as rows at.. of the new halo into buffer `name`: those of its first `first` rows below the
        owned rows first .. end - 1, the others after them."""
        below = min(max(first - at, 0), len(values))
        if below:
            self.sim.backend.write_rows(name, at, values[:below])
        if below < len(values):
            self.sim.backend.write_rows(name, end + at + below - first, values[below:])

    def owned(self):
        """The particles this rank owns after a step (LOADED arrays, in the device's order), or at the start."""
        if self.starts is None:
            return self.start_owned
        first, end = self.owned_rows()
        return {name: self.sim.backend.read_rows(name, first, end) for name in LOADED}

    def write_piece(self, series, out_dir, step, t):
        """Each rank writes its owned particles (in the device's order) as its piece of snapshot `step`; rank 0
        (`series`, the others None) lists the pieces in the run folder's manifest first and, once all are written,
        names them in the snapshot's .pvtp, listed in the .pvd."""
        dim, pieces, owned = self.sim.dim, None, self.owned()
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
        status, checked there as read() checks a 1-rank run's (Simulation.checked); rank 0 keeps the arrays of the
        checkpoint and final.npz of that (`checkpoint`, `final`): those a 1-rank run writes, of every particle in id
        order. No device holds more than its share. A rank's rows cross as raw buffers (Send), a buffer at a time
        in pieces of PIECE rows (an MPI count is 32-bit), their ids first; the energy bound (the first gather's)
        goes to every rank."""
        sim, owned = self.sim, self.owned()
        statuses = self.comm.gather(sim.backend.read_buffer("grid_status"), root=0)
        counts = self.comm.gather(len(owned["particle_id"]), root=0)
        if self.rank == 0:
            self.assemble(owned, statuses, counts)
        else:
            for name in SENT:
                for k in range(0, len(owned[name]), PIECE):
                    self.comm.Send(owned[name][k:k + PIECE], dest=0)
        sim.energy_start = self.comm.bcast(sim.energy_start, root=0)
        sim.checked_step = sim.step_count

    def assemble(self, owned, statuses, counts):
        """Rank 0's part of gather: its own particles `owned` and every other rank's (`counts` of them, received),
        each buffer's rows placed at their ids (every id once: checked), read as a 1-rank run reads them."""
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
        state = sim.checked(state, statuses)
        carried = sim.backend.read([name for name in CARRIED if name not in LOADED])
        carried["control"][CONTROL_REBUILD] = 1  # (a rank's next step builds its lists: every step does)
        carried = {name: whole[name] if name in whole else carried[name] for name in CARRIED}
        params = sim.params_of(self.total)  # (every particle owned: a 1-rank run's)
        self.checkpoint, self.final = sim.checkpoint_of(carried, params), final_arrays(sim, state, params)

    def received(self, like, count, source):
        """`count` rows of a buffer (`like`'s dtype and row shape) that rank `source` sends (gather)."""
        rows = np.empty((count, *like.shape[1:]), like.dtype)
        for k in range(0, count, PIECE):
            self.comm.Recv(rows[k:k + PIECE], source=source)
        return rows

    def check(self):
        """Check the particles this rank owns, without gathering them, as read() checks a 1-rank run's
        (sphcore.health): every per-particle buffer's owned rows, in id order (a message names a particle by its
        id), this rank's grid status, and the energy bound with the energy summed over the ranks (in rank order)
        and the fastest particle the fastest of theirs (allgather of health.energy_figures). A failure on any
        rank is raised by the first rank that found one (main prints it and aborts every rank), which the
        others wait for."""
        sim, backend = self.sim, self.sim.backend
        first, end = self.owned_rows()
        state = in_particle_order({name: backend.read_rows(name, first, end) for name in PARTICLE_BUFFERS}, sim.dim)
        ids = state["particle_id"]
        figures = self.comm.allgather(health.energy_figures(sim.scene, state, ids))
        world = (sum(f[0] for f in figures), *max(figures, key=lambda f: (f[1], -f[2]))[1:])
        failure = None
        try:
            health.check_state(sim, state, ids, world)
            health.check_grid(sim, backend.read_buffer("grid_status"))
        except SimulationError as e:
            failure = e
        failed = [r for r, found in enumerate(self.comm.allgather(failure is not None)) if found]
        if failed and failed[0] == self.rank:
            raise failure
        if failed:
            self.comm.Barrier()  # (not passed: rank failed[0] aborts every rank)
        sim.checked_step = sim.step_count

    def stopped(self, signals):
        """The first signal any rank received (sphcore.signals.Signals: `signals`), or 0: every rank stops at the
        same step."""
        from mpi4py import MPI
        return self.comm.allreduce(signals.received or 0, op=MPI.MAX)


def run(scene, steps=None, out_dir=None, progress=True, overwrite=False, comm=None, backend="numba",
        local_size=128, device=None):
    """Run `scene` decomposed over the ranks of `comm` (default: MPI's world), as sphcore.run does on one: snapshots
    every time.output_every steps (or time.output_interval), a .vtp piece a rank and their .pvtp (write_piece), each
    rank's particles checked first (Rank.check); a checkpoint at the start, every time.checkpoint_every steps, at
    the end and where SIGINT or SIGTERM stops the run (on any rank: every rank stops at that step, Stopped), and
    final.npz, gathered on rank 0's host in particle-id order, checked there and written into `out_dir` (a
    checkpoint resumes on one rank: sphcore.resume). Return the final arrays on rank 0, None on the others. On
    Vulkan each rank runs on `device` (an index or part of a name), by default its host's rank-th GPU
    (rank_device)."""
    comm = comm or world()
    check(scene, backend)
    options = {"local_size": local_size}
    if backend == "vulkan":
        from mpi4py import MPI
        options["device"] = device if device is not None else rank_device(
            comm.Split_type(MPI.COMM_TYPE_SHARED).Get_rank())
    scene, steps, out_dir = _run_arguments(scene, backend, steps, out_dir, progress, None, overwrite, options)
    root = comm.Get_rank() == 0
    schedule = Schedule(scene, steps)
    with Signals() as signals, folder.RunFolder(out_dir) if root else contextlib.nullcontext() as run_folder:
        if root:  # (rank 0 writes)
            folder.remove_stale_temporaries(out_dir)
            run_folder.prepare(scene["name"], resume=False, overwrite=overwrite)
            run_folder.write_bytes("scene.json", scene.to_json().encode())
            series = SnapshotSeries(out_dir, scene["name"], folder=run_folder)
        cuts, keep = share(scene, comm.Get_size(), comm.Get_rank(), buffer_dtype("particle_x", scene["physics.precision"]))
        with Simulation(scene, backend, id_order=True, keep=keep, poll=signals.poll, **options) as sim:
            rank = Rank(sim, comm, cuts)

            def save_checkpoint():  # (every rank: the gather)
                rank.gather()  # (the start's: its energy the bound of the later checks)
                if root:
                    run_folder.savez(CHECKPOINT, **rank.checkpoint)

            def snapshot():
                rank.write_piece(series if root else None, out_dir, sim.step_count, sim.time)

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
                    if due:
                        rank.gather()  # (checked there)
                    if schedule.snapshot_due(sim, before, t):
                        if not due:
                            rank.check()
                        snapshot()
                    if due and root:
                        run_folder.savez(CHECKPOINT, **rank.checkpoint)
            if stopped and not schedule.done(sim, t):
                raise Stopped(stopped, f"interrupted by {signal.Signals(stopped).name} at step {sim.step_count} "
                              f"{schedule.of(sim)} on {rank.size} ranks; checkpoint written: continue with "
                              f"`sphcore run --resume {out_dir}` (on one rank)")
            if not root:
                return None
            run_folder.savez("final.npz", **rank.final)
            return rank.final


def main(run_args):
    """`sphcore run` under mpiexec: run_args (scene, steps, out, overwrite, local_size, backend, device) on every
    rank; an error on a rank prints `rank R: message` and aborts every rank. A signal stops every rank at one step
    (Stopped): rank 0 says so, the others exit with the same status."""
    comm = world()
    try:
        return run(**run_args, comm=comm)
    except Stopped as e:
        if comm.Get_rank() == 0 or comm.Get_size() == 1:
            raise
        sys.exit(128 + e.signum)
    except BaseException as e:
        print(f"sphcore: error: rank {comm.Get_rank()} of {comm.Get_size()}: {e}", file=sys.stderr, flush=True)
        if comm.Get_size() > 1:
            comm.Abort(1)
        raise
