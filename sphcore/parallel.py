"""One scene on N MPI ranks (issue 34, first slice; docs/parallel.md): `mpiexec -n N sphcore run SCENE`, or
`sphcore.parallel.run` under mpiexec, on the numba or the Vulkan backend (rank r of a host on its r-th GPU).

Each rank holds a Simulation of the scene (sphcore.stepper) and owns a slab of the domain (sphcore.decomposition).
Every step, through host memory (mpi4py's pickled alltoall):
  [1] the cuts: each rank's particles per cell layer, summed over the ranks (Allreduce), balanced (balance);
  [2] each rank sends every other the particles it owns that the other owns now (migration) or must see (halo);
  [3] each rank loads what it holds, in global-id order (Simulation.load), so every cell's particles are in
      id order after the step's sort, on any number of ranks: a sum over a cell runs in the same order;
  [4] it runs the plan's stages (on Vulkan in two submissions), reduce_dt replaced by the maximum over the
      ranks' owned particles (Allreduce): every rank's choose_dt takes the same dt, the minimum over the ranks;
  [5] it keeps its owned particles' new state.
Snapshots are ParaView's parallel files: each rank writes its owned particles as one .vtp piece, rank 0 the
.pvtp naming the pieces, listed in the .pvd. The checkpoint and final.npz are gathered on rank 0 in particle-id
order and written there as a 1-rank run writes them; a checkpoint resumes on one rank (`sphcore run --resume`).
Progress and messages come from rank 0. An error on any rank stops every rank (MPI Abort) after printing the
rank's message.

N ranks give bitwise the state of this driver on 1 rank (tests/test_parallel.py). A plain Simulation orders a
cell's particles by their previous index, not their id, so its sums run in another order: a few ulps away at
first, then as far apart as a flow lets two runs drift.
"""
import contextlib
import os
import sys
import time
from pathlib import Path

import numpy as np

from sphcore import decomposition, folder
from sphcore.checkpoint import CHECKPOINT
from sphcore.errors import SceneError, SimulationError
from sphcore.output import SnapshotSeries, write_vtp
from sphcore.runner import Schedule, _run_arguments, final_arrays
from sphcore.stepper import LOADED, Simulation
from sphcore.vk_runner import Context

# Launchers' environment variables with the world's size (Open MPI; MPICH's Hydra and Intel MPI, srun with PMI).
# Not SLURM_NTASKS: a job's every process sees it, one started without srun too.
SIZE_VARIABLES = ("OMPI_COMM_WORLD_SIZE", "PMI_SIZE")


def launched_ranks():
    """The ranks mpiexec started this process among (1 where it did not), read from the environment: the CLI
    imports mpi4py only under mpiexec."""
    for name in SIZE_VARIABLES:
        if os.environ.get(name, "").isdigit():
            return int(os.environ[name])
    return 1


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


def in_id_order(parts):
    """The particle arrays of `parts` (a list of dicts) in one dict, rows in global-id order."""
    joined = {name: np.concatenate([p[name] for p in parts]) for name in LOADED}
    return take(joined, np.argsort(joined["particle_id"], kind="stable"))


class Rank:
    """One rank's share of a Simulation `sim` over MPI communicator `comm`: its owned particles between steps
    (`owned`, per-particle arrays of LOADED, in the device's order: what it holds is sorted by id at each load),
    the cuts, and the step (module docstring)."""

    def __init__(self, sim, comm):
        self.sim, self.comm, self.rank, self.size = sim, comm, comm.Get_rank(), comm.Get_size()
        names = [stage.name for stage in sim.stages]
        cut = names.index("reduce_dt") if "reduce_dt" in names else len(names)
        self.before_dt, self.after_dt = sim.stages[:cut], sim.stages[cut + 1:]  # (reduce_dt: over the ranks)
        self.adaptive = cut < len(names)
        self.seconds = dict.fromkeys(("exchange", "load", "stages", "dt", "keep"), 0.0)  # (a profile of step)
        P = sim.params[0]
        self.axis = decomposition.slab_axis(sim.dim)
        self.box_min = float(P["box_min"][self.axis])
        self.cell_size = 1.0 / float(P["inv_cell"])
        self.layers = int(P["grid_dim"][self.axis])
        self.width = decomposition.halo_width(sim.scene)
        everything = in_id_order([sim.backend.read(LOADED)])  # the start, the same on every rank
        layer, _ = self.decompose(everything, summed=False)
        self.owned = take(everything, decomposition.owners(layer, self.cuts) == self.rank)

    def decompose(self, particles, summed=True):
        """Balance the cuts over the ranks' `particles` (the owned ones; at the start, unless `summed`, every
        rank's all, whose counts are already the world's): (each particle's layer, its coordinate on the axis)."""
        from mpi4py import MPI
        x = particles["particle_x"][:, self.axis]
        layer = decomposition.layers_of(x, self.box_min, self.cell_size, self.layers)
        counts = np.bincount(layer, minlength=self.layers).astype(np.int64)
        if summed:
            self.comm.Allreduce(MPI.IN_PLACE, counts, op=MPI.SUM)
        self.cuts = decomposition.balance(counts, self.size)
        return layer, x

    def step(self):
        """One step of the decomposed run ([1]-[5] of the module docstring); the seconds of each part add up in
        `seconds`: exchange ([1], [2]: the cuts and the alltoall, staged through host memory), load ([3]), stages
        ([4] but the dt), dt (its Allreduce, with the reads of v and a), keep ([5]: the read back)."""
        from mpi4py import MPI
        start = time.perf_counter()
        layer, x = self.decompose(self.owned)  # [1]
        owner = decomposition.owners(layer, self.cuts)
        sends = [take(self.owned, decomposition.needed_by(x, owner, self.cuts, self.box_min, self.cell_size,
                                                          self.width, r)) for r in range(self.size)]
        kept, sends[self.rank] = sends[self.rank], None  # (its own share stays: no message over 2 GiB on 1 rank)
        received = self.comm.alltoall(sends)  # [2]
        received[self.rank] = kept
        held = in_id_order(received)
        mine = decomposition.owners(decomposition.layers_of(held["particle_x"][:, self.axis], self.box_min,
                                                            self.cell_size, self.layers), self.cuts) == self.rank
        mine_ids = held["particle_id"][mine]
        if not mine.any():  # (its dt would not be the world's: choose_dt reads at least one partial)
            raise SimulationError(f"rank {self.rank} owns no particle at step {self.sim.step_count}: the "
                                  f"{self.size} slabs are too thin for the flow; use fewer ranks")
        start = self.lap("exchange", start)
        self.sim.load(held)  # [3]
        start = self.lap("load", start)
        backend = self.sim.backend
        backend.run_stages(self.before_dt)  # [4]
        start = self.lap("stages", start)
        if self.adaptive:
            self.reduce_dt(mine_ids, MPI)
            start = self.lap("dt", start)
            backend.run_stages(self.after_dt)
            start = self.lap("stages", start)
        after = backend.read(LOADED)  # [5]
        self.owned = take(after, np.isin(after["particle_id"], mine_ids))
        self.lap("keep", start)
        self.sim.step_count += 1

    def lap(self, part, start):
        """Add the seconds since `start` to `part`'s; return now."""
        now = time.perf_counter()
        self.seconds[part] += now - start
        return now

    def reduce_dt(self, mine_ids, MPI):
        """reduce_dt over every rank's owned particles: the largest |v|^2 and |a|^2 (in the shader's order of
        operations and precision; a maximum is exact in any order) into the first of dt_partial, zeros after:
        choose_dt then takes the world's dt on every rank."""
        backend = self.sim.backend
        v, a = backend.read_buffer("particle_v"), backend.read_buffer("particle_a")
        mine = np.isin(backend.read_buffer("particle_id"), mine_ids)
        v, a = v[mine], a[mine]
        largest = np.zeros(2, v.dtype)
        if len(v):
            largest[0] = (v[:, 0] * v[:, 0] + v[:, 1] * v[:, 1] + v[:, 2] * v[:, 2]).max()
            largest[1] = (a[:, 0] * a[:, 0] + a[:, 1] * a[:, 1] + a[:, 2] * a[:, 2]).max()
        self.comm.Allreduce(MPI.IN_PLACE, largest, op=MPI.MAX)
        partial = np.zeros_like(backend.read_buffer("dt_partial"))
        partial[0] = largest
        backend.write_buffer("dt_partial", partial)

    def write_piece(self, series, out_dir, step, t):
        """Each rank writes its owned particles (in the device's order) as its piece of snapshot `step`; rank 0
        (`series`, the others None) lists the pieces in the run folder's manifest first and, once all are written,
        names them in the snapshot's .pvtp, listed in the .pvd."""
        dim, pieces = self.sim.dim, None
        x = self.owned["particle_x"][:, :dim]
        data = {"velocity": self.owned["particle_v"][:, :dim], "density": self.owned["particle_rho"],
                "pressure": self.owned["particle_p"]}
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
        """Rank 0: load every rank's owned particles, in id order, and return sim.read() (checked); others: None.
        (The next step loads the rank's own share again.) A message a rank: a pickled gather's counts and
        displacements are 32-bit, and its whole would pass 2 GiB at about 27 M particles (80 bytes each)."""
        if self.rank != 0:
            self.comm.send(self.owned, dest=0)
            return None
        self.sim.load(in_id_order([self.owned] + [self.comm.recv(source=r) for r in range(1, self.size)]))
        return self.sim.read()


def run(scene, steps=None, out_dir=None, progress=True, overwrite=False, comm=None, backend="numba",
        local_size=128, device=None):
    """Run `scene` decomposed over the ranks of `comm` (default: MPI's world), as sphcore.run does on one: snapshots
    every time.output_every steps (or time.output_interval), a .vtp piece a rank and their .pvtp (write_piece); a
    checkpoint at the start, every time.checkpoint_every steps and at the end, and final.npz, gathered on rank 0
    in particle-id order and written there into `out_dir` (a checkpoint resumes on one rank: sphcore.resume).
    Return the final arrays on rank 0, None on the others. On Vulkan each rank runs on `device` (an index or part
    of a name), by default its host's rank-th GPU (rank_device)."""
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
    with folder.RunFolder(out_dir) if root else contextlib.nullcontext() as run_folder:  # (rank 0 writes)
        if root:
            folder.remove_stale_temporaries(out_dir)
            run_folder.prepare(scene["name"], resume=False, overwrite=overwrite)
            run_folder.write_bytes("scene.json", scene.to_json().encode())
            series = SnapshotSeries(out_dir, scene["name"], folder=run_folder)
        with Simulation(scene, backend, **options) as sim:
            state = sim.read()  # (every rank: the start's energy, the bound of the later checks)
            rank = Rank(sim, comm)

            def snapshot():
                rank.write_piece(series if root else None, out_dir, sim.step_count, sim.time)

            snapshot()
            if root:
                run_folder.savez(CHECKPOINT, **sim.checkpoint())
            t = schedule.time(sim)
            with schedule.progress(sim, t, disable=not (progress and root),
                                   desc=f"{scene['name']} [{backend} x {rank.size} ranks]") as bar:
                while not schedule.done(sim, t):
                    rank.step()
                    before, t = t, schedule.time(sim)
                    bar.update(1 if schedule.end_time is None else min(t, schedule.end_time) - before)
                    if schedule.snapshot_due(sim, before, t):
                        snapshot()
                    if schedule.checkpoint_due(sim) or schedule.done(sim, t):
                        state = rank.gather()
                        if root:
                            run_folder.savez(CHECKPOINT, **sim.checkpoint())
            if not root:
                return None
            arrays = final_arrays(sim, state)
            run_folder.savez("final.npz", **arrays)
            return arrays


def main(run_args):
    """`sphcore run` under mpiexec: run_args (scene, steps, out, overwrite, local_size, backend, device) on every
    rank; an error on a rank prints `rank R: message` and aborts every rank."""
    comm = world()
    try:
        return run(**run_args, comm=comm)
    except BaseException as e:
        print(f"sphcore: error: rank {comm.Get_rank()} of {comm.Get_size()}: {e}", file=sys.stderr, flush=True)
        if comm.Get_size() > 1:
            comm.Abort(1)
        raise
