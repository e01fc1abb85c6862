"""A scene's particles on a backend, stepped: `Simulation` (sphcore.simulation is its public face).

The stepping alone: the health checks of a read are in sphcore.health, the run with its snapshots,
checkpoints and resume in sphcore.runner, and what a pressure solver adds in sphcore.solvers.
"""
import functools
import math
import threading

import numpy as np

from sphcore import folder, gauges, geometry, health, memory
from sphcore.backends import check_options, make_backend
from sphcore.checkpoint import CARRIED
from sphcore.errors import CheckpointError, SimulationError
from sphcore.output import SnapshotSeries
from sphcore.params import PARAMS_DTYPE
from sphcore.plan import BUFFERS, PARTICLE_BUFFERS, density_stages, empty_state, in_particle_order, plan
from sphcore.signals import HeldInterrupt
from sphcore.solvers import solver_for
from sphcore.sph.dfsph import CONTROL_REBUILD
from sphcore.stage import REUSE
from sphcore.surface import particle_surface


# What read() takes from the backend: the per-particle state, the grid's status and the carried buffers.
READ = tuple(dict.fromkeys((*PARTICLE_BUFFERS, "grid_status", *CARRIED)))
# The per-particle buffers of CARRIED: what Simulation.load takes.
LOADED = tuple(name for name in CARRIED if BUFFERS[name][2] == "particles")
# A rank's fields of the parameter block (params.glsl; sphcore.parallel.Rank.slab_fields): the cells of its slab, those
# the grid's cell stages take, and the coordinates along the slab axis of the rows whose density it sums.
SLAB_FIELDS = ("owned_first", "owned_end", "cells_first", "cells_end", "summed_min", "summed_max")


def wall_particles(scene):
    """The bodies' wall particles as a Simulation numbers them (ids fluid_count and up, body by body, each in its
    lattice's order): positions (N_w, dim) and each one's body index."""
    walls, body = scene.wall_positions()
    order = np.argsort(body, kind="stable")
    return walls[order], body[order]


def _exclusive(method):
    """A method of Simulation that uses its backend: refused (SimulationError) once the simulation is
    closed, and while another thread is inside one of these methods (a backend's buffers and a Vulkan
    queue are for one thread at a time; two threads stepping one state turned it NaN, or corrupted the
    heap). The same thread may nest them (checkpoint reads, a replay restores and steps)."""
    @functools.wraps(method)
    def use(self, *args, **kwargs):
        if not self._lock.acquire(blocking=False):
            raise _in_use(self, method.__name__)
        outer = self._user is None
        try:
            if outer:
                self._user = (threading.current_thread().name, method.__name__)
            if self._closed:
                raise SimulationError(f"Simulation.{method.__name__}(): this Simulation of {self.scene['name']!r} is "
                                      "closed (its buffers are freed); make a new Simulation")
            return method(self, *args, **kwargs)
        finally:
            if outer:
                self._user = None
            self._lock.release()

    return use


def _in_use(sim, name):
    """The error for a call of Simulation.`name` while another thread is inside `sim`."""
    thread, doing = sim._user or ("another thread", "a call")
    return SimulationError(f"Simulation.{name}() from thread {threading.current_thread().name!r} while thread "
                           f"{thread!r} is in Simulation.{doing}() on the same Simulation: one thread at a time; wait "
                           "for it, or give each thread its own Simulation")


class Simulation:
    """A scene's particles on one backend ("numba", the default, or "vulkan"; backend_options:
    local_size, and for Vulkan device and validation).

    `step(k)` runs k steps; `read()` checks the state and returns it in particle order as numpy
    arrays: particle_x, particle_v, particle_a (N, dim), particle_rho, particle_p (N,) and more, of the
    fluid; the bodies' wall particles' are then in `walls` (their particle_a: the fluid's force on them per
    unit mass; `body`: each one's body index), and `take_gauge_rows()` gives the gauges' samples;
    `time` and `step_count` say where the run is. `write_snapshot(dir)` writes a VTK snapshot,
    `surface()` extracts the fluid's surface (3D). `checkpoint()` and `restore(arrays)` save and
    put back everything a later step depends on. Use it in a `with` block, or call close().

    >>> import sphcore
    >>> scene = sphcore.Scene.from_dict({"fluid": {"spacing": 0.05}})  # 6 x 6 particles
    >>> with sphcore.Simulation(scene, backend="numba") as sim:
    ...     sim.step(10)
    ...     state = sim.read()
    ...     print(sim.step_count, state["particle_x"].shape, state["particle_rho"].dtype)
    10 (36, 2) float32
    """

    solver_log = property(lambda self: self.solver.log, doc="DFSPH's SolverLog (sphcore.solvers.dfsph)")
    _carried = None  # the CARRIED buffers as the last read() saw them
    walls = {}  # the bodies' wall particles' state as the last read() saw them
    energy_start = None  # the energy at the first read, the bound for every later one
    _closed = False
    _user = None  # (thread name, method) of the call inside the simulation now (_exclusive)

    def __init__(self, scene, backend="numba", *, poll=None, id_order=False, keep=None, **backend_options):
        """`poll()` is called between the start-up's stages (after each kernel is compiled): a safe
        point where sphcore.run stops on a signal. `id_order`: the grid orders each cell's particles by id,
        not by their previous index (ID_ORDER: a rank of sphcore.parallel, whose rows change every step).
        `keep`: a mask over the scene's particles (by id) of those this simulation holds, alone (a rank's share:
        its own and its halo; ids stay the scene's). The host memory the run will need is checked
        first (sphcore.memory): a run that would not fit is refused before anything is allocated. The
        simulation keeps its own copy of `scene`, checked again (Scene.validated): a change made to the
        scene after it was loaded is checked, and one made later does not reach the run."""
        self._lock = threading.RLock()
        scene = scene.validated()
        check_options(backend, backend_options)
        held = None if keep is None else int(np.count_nonzero(keep))
        memory.check(scene, backend, n=held)  # Vulkan: its device memory is checked once the device is known
        poll = poll or (lambda: None)
        if backend == "vulkan":  # lavapipe's device memory is host memory
            backend_options.setdefault("before_allocating",
                                       lambda ctx: memory.check(scene, backend, ctx.device_type == "CPU", n=held))
        self.scene = scene
        # the fluid's particles, then the bodies' wall particles, body by body (fixed: ids fluid_count and up)
        x0 = scene.initial_positions()
        walls, self.wall_body = wall_particles(scene)
        self.fluid_count = len(x0)
        self.buried = geometry.buried_keys(walls, scene["domain.box_min"], scene["domain.box_max"],
                                           scene["fluid.spacing"])  # (health.check_bodies)
        x0 = np.concatenate([x0, walls]).astype(x0.dtype, copy=False)
        ids = np.arange(len(x0)) if keep is None else np.flatnonzero(keep)
        x0 = x0[ids] if keep is not None else x0
        self.n, self.dim = len(x0), scene.dim
        self.params, self._params_bytes = scene.params(self.n, self.fluid_count), None
        self.spec = scene.spec_for(backend)._replace(ID_ORDER=id_order)  # (the state equation's lists: spec_for)
        counts = np.bincount(self.wall_body, minlength=len(scene.bodies)).tolist()
        firsts = (self.fluid_count + np.cumsum([0] + counts[:-1])).tolist()
        self.body_ids = {body.name: (first, count, body.centroid)  # each body's ids: first, count; its centre
                         for body, first, count in zip(scene.bodies, firsts, counts)}
        gauge_table = gauges.table(scene, self.body_ids)  # (the scene's [[gauges]], or None)
        state = empty_state(self.params, scene["physics.precision"], scene["domain.obstacles"],
                            self.spec.MAX_NEIGHBOURS, self.spec.GRADIENTS, gauge_table)
        self.gauges = None if gauge_table is None else gauges.GaugeReader(scene, gauge_table[1])
        self.gauge_rows = []  # the samples read from the device and not yet taken (take_gauge_rows)
        state["particle_id"][:] = ids
        state["particle_x"][:, :self.dim] = x0
        state["particle_rho"][:] = scene.initial_density(x0)  # the state's density where it is integrated (continuity)
        state["particle_rho"][ids >= self.fluid_count] = scene["fluid.rest_density"]  # (wall_pressure sets the walls')
        self.solver = solver_for(scene)  # what the pressure solver adds to the step (sphcore.solvers)
        self.solver.init_state(state)
        self.stages = plan(scene)
        self.density_stages = [s for s in density_stages(scene) if s.when != REUSE]  # (a build's: the scan)
        self.backend = make_backend(backend, self.params, state, self.stages, self.spec,
                                    precision=scene["physics.precision"], **backend_options)
        del state, x0
        poll()
        if hasattr(self.backend, "warm_up"):
            self.backend.warm_up(poll)
        self.compute_densities()  # the start's: its energy, and its first snapshot's density
        self.step_count = 0
        self.checked_step = 0

    @_exclusive
    def compute_densities(self):
        """Density and pressure of the current positions (a step without its forces and motion)."""
        for stage in self.density_stages:
            self.backend.run_stage(stage)

    @property
    @_exclusive
    def time(self):
        """The simulated time [s]: steps times dt, or with time.dt = "adaptive" the sum of the steps' dts,
        kept on the device (time_state: a compensated float32 pair, read here, never per step)."""
        if self.scene.adaptive_dt:
            state = self.backend.read_buffer("time_state")[0]
            return float(state[2]) + float(state[3])
        return self.step_count * float(self.params[0]["dt"])

    @property
    @_exclusive
    def dt(self):
        """The last step's dt [s]: time.dt, or the device's where it is adaptive (before the first step,
        the scene's estimate)."""
        if self.scene.adaptive_dt:
            dt = float(self.backend.read_buffer("time_state")[0][0])
            return dt if dt > 0 else self.scene.dt
        return float(self.params[0]["dt"])

    @_exclusive
    def advance(self, steps):
        """Run `steps` steps in chunks (a step on numba, a submission of steps_per_submit on Vulkan: all or
        nothing), each counted in step_count as it ends. A Ctrl-C (SIGINT under Python's default handler, in
        the main thread) is held until the chunk it arrived in has run, then raised as KeyboardInterrupt:
        step_count and time stay true, and the state is that of a whole step (sphcore.signals.HeldInterrupt).
        The solver's log is read at least every solver.collect_every steps, and at the end (sphcore.solvers)."""
        chunk, collected, end = getattr(self.backend, "steps_per_submit", 1), self.step_count, self.step_count + steps
        every = self.solver.collect_every
        with HeldInterrupt() as held:
            while self.step_count < end and held.received is None:
                k = min(chunk, end - self.step_count, every - (self.step_count - collected))
                if self.gauges is not None:  # (the gauges' rings are read before a chunk could fill them)
                    if self.gauges.since + k > gauges.GAUGE_SLOTS:
                        self.read_gauges()
                    k = min(k, gauges.GAUGE_SLOTS - self.gauges.since)
                    self.gauges.since += k
                self.backend.step(k)
                self.step_count += k
                if self.step_count - collected == every or self.step_count == end or held.received is not None:
                    self.solver.collect(self.backend, collected, self.step_count)
                    collected = self.step_count
        if held.received is not None:
            raise KeyboardInterrupt(f"stopped after step {self.step_count} ({self.step_count - (end - steps)} of "
                                    f"the {steps} asked for)")

    @_exclusive
    def read_gauges(self):
        """Read the samples the gauges took since the last read from the device into gauge_rows."""
        if self.gauges is not None:
            rows = self.gauges.read(self.backend)
            self.gauge_rows = rows if not self.gauge_rows else [np.concatenate(p) for p in zip(self.gauge_rows, rows)]

    @_exclusive
    def take_gauge_rows(self):
        """The samples of each gauge (scene [[gauges]]) since the last call: a list, one array (rows, time and the
        quantity's components) a gauge, in the order of the scene's gauges; [] without gauges."""
        self.read_gauges()
        rows, self.gauge_rows = self.gauge_rows, []
        return rows

    @_exclusive
    def read(self):
        """The fluid's state in particle order (vectors of `dim` components), checked; the bodies' wall particles'
        in `walls` (with their body's index, `body`). A check that fails more than one step after the last good one
        is replayed from there a step at a time, so the error names the first step at which the state went wrong."""
        raw = self.backend.read(READ)  # (not the scratch, the grid or the neighbour lists: each step rewrites them)
        try:
            state = self.checked(in_particle_order(raw, self.dim), [raw["grid_status"]])
        except SimulationError:
            if self._carried is not None and self.step_count - self.checked_step > 1:
                self._replay()
            raise
        self._carried = {name: raw[name] for name in CARRIED}
        self.build_lists_next()
        return state

    def checked(self, state, statuses):
        """The fluid's part of `state` (every particle's arrays, in particle order, vectors of `dim` components),
        checked with the grid's `statuses` (one a backend: sphcore.health), the walls' part kept in `walls`; the
        step is the last good one from now on, and the first state checked sets the energy bound. read() checks
        the backend's buffers so; a rank of sphcore.parallel, every rank's particles gathered on the host."""
        self.walls = {name: values[self.fluid_count:] for name, values in state.items()}
        self.walls["body"] = self.wall_body
        state = {name: values[:self.fluid_count] for name, values in state.items()}
        health.check_state(self, state)
        for status in statuses:
            health.check_grid(self, status)
        self.checked_step = self.step_count
        if self.energy_start is None:
            self.energy_start = sum(health.energy_terms(self.scene, state))
        return state

    @_exclusive
    def build_lists_next(self):
        """Reused lists (physics.list_skin): the next step builds them. The lists are not in a checkpoint, so a
        run resumed from one (restore) builds at its first step; to step on bitwise as the run that wrote it,
        that run builds there too: after every read of the state (checkpoint() reads), and in sphcore.run
        after each of its chunks of steps, where a signal may stop it and write a checkpoint whether or not
        the run never stopped reads there. (A replay, which reads every step, builds every step: its sums run
        in another order than the run it replays.)"""
        if self.spec.LIST_SKIN:
            control = self.backend.read_buffer("control")
            control[CONTROL_REBUILD] = 1
            self.backend.write_buffer("control", control)

    def _replay(self):
        """Step again from the last good state, one step at a time, until a check fails (it raises)."""
        failed_at = self.step_count
        self.restore({"step": np.int64(self.checked_step), "energy_start": np.float64(self.energy_start),
                      **{f"buffer_{k}": v for k, v in self._carried.items()}})
        while self.step_count < failed_at:
            self.advance(1)
            self.read()

    def energy(self, state):
        """(kinetic + potential, internal energy) of `state` [J; 2D: J/m] (sphcore.health.energy_terms)."""
        return health.energy_terms(self.scene, state)

    @property
    def device_name(self):
        """Where the steps run: the Vulkan device's name, or "cpu" for the numba mirrors."""
        ctx = getattr(self.backend, "ctx", None)
        return ctx.device_name if ctx is not None else "cpu"

    @_exclusive
    def checkpoint(self):
        """The arrays of a checkpoint at the current step (read and checked first: a blown-up state
        is never saved). The buffers are kept in the backend's order, not in particle order: the
        grid orders each cell's particles by their previous index, so a state put back in particle
        order would continue with its sums in another order, a few ulps away."""
        if self._carried is None or self.checked_step != self.step_count:
            self.read()
        return self.checkpoint_of(self._carried, self.params)

    @_exclusive
    def checkpoint_of(self, carried, params):
        """The arrays of a checkpoint at the current step of the CARRIED buffers `carried` (checked) and the
        parameter block `params`: checkpoint()'s of the backend's, a rank of sphcore.parallel's of every rank's
        particles gathered on the host (params_of their count)."""
        arrays = {f"buffer_{name}": values for name, values in carried.items()}
        # the parameter block as its bytes: numpy's .npy writer leaves a record's padding uninitialised
        arrays.update(energy_start=np.float64(self.energy_start), step=np.int64(self.step_count),
                      scene=np.array(self.scene.to_json()),
                      params=params.view(np.uint8), backend=np.array(self.backend.name), device=np.array(self.device_name))
        arrays.update(self.solver.checkpoint_arrays())
        if self.gauges is not None:  # the samples taken so far and each gauge's next time (a resume's rows)
            arrays["gauge_state"] = self.backend.read_buffer("gauge_state")
        return arrays

    @_exclusive
    def load(self, particles, slab=(0, 0)):
        """Hold another set of particles from now on: `particles` maps every per-particle buffer of CARRIED
        (LOADED) to an array, rows in any order, with the particles' global ids in particle_id (ids of
        fluid_count and up are the bodies' wall particles). The other carried buffers (the time, the grid's
        status, the iteration control), the obstacles and the gauges (their table and state) are kept, every other buffer is zeroed (as at the
        start), and the next step builds its neighbour lists. A rank of sphcore.parallel loads its owned and halo
        particles at the start; `slab`: the cells of its slab, those its particles can be in, and the coordinates
        of the rows whose density it sums (SLAB_FIELDS; (0, 0): every particle is owned, every cell taken). The
        backend stays (no compile, no new Vulkan device): its buffers keep their size while the set fits, n in the
        parameter block (Vulkan: its uniform) becomes the count, and the dispatch sizes follow it (backends: load).
        read() and checkpoint() check and save the whole scene: call them with every particle loaded. With gauges,
        only a rank's (slab given: its gauges sample its slab)."""
        if self.gauges is not None and not any(slab):
            raise SimulationError("Simulation.load(): the scene's gauges sample by particle id across the whole "
                                  "scene; a scene with [[gauges]] cannot load another particle set yet")
        kept = [name for name in CARRIED if name not in LOADED] + ["obstacle_box", "gauge_table", "gauge_state"]
        params = self._count(len(particles["particle_id"]), slab)
        self.backend.load(params, {name: particles[name] for name in LOADED}, kept)

    @_exclusive
    def resize(self, n, slab=(0, 0), ahead=False):
        """Hold n particles from now on, the rows up to the old count as they are (a rank of sphcore.parallel
        writes the rows that change: backend.write_rows); `slab` as load's. The next step builds its
        neighbour lists. (`ahead`: the backend's resize's.)"""
        self.backend.resize(self._count(n, slab), ahead)

    def params_of(self, n, slab=(0, 0)):
        """The parameter block of n particles (the fluid's first) and `slab` (load's): the bytes of the scene's
        block, made once (scene.params: 75 us, which a rank of sphcore.parallel would spend every step), with those
        set. (A byte copy: a record's copy() leaves its padding unset, and a checkpoint keeps every byte.)"""
        if self._params_bytes is None:
            self._params_bytes = self.scene.params(0, self.fluid_count).tobytes()
        params = np.frombuffer(bytearray(self._params_bytes), PARAMS_DTYPE)
        params[0]["n"] = n
        for field, value in zip(SLAB_FIELDS, slab):
            params[0][field] = value
        return params

    def _count(self, n, slab):
        """The parameter block of n particles and `slab`, taken as the simulation's; the next step builds its
        lists (those of the set held before are of other rows)."""
        params = self.params_of(n, slab)
        self.params, self.n, self._carried = params, n, None
        self.backend.write_mapped("control", CONTROL_REBUILD, [1])  # (while a submission left running goes on)
        return params

    @_exclusive
    def restore(self, arrays, keep=None, slab=(0, 0)):
        """Continue from `arrays` (of `checkpoint()`, possibly on another backend): its buffers
        replace the backend's, its step becomes the step count. The energy bound is not taken
        from `arrays`: it is the energy of the scene's initial state, which the backend holds until
        the first restore (a stored energy_start that differs from it is refused). A rank of sphcore.parallel
        holds the rows `keep` (a mask) of the checkpoint's particles from then on (load: `slab` its slab);
        it has its energy_start of the initial state (gathered) first."""
        if self.energy_start is None:
            self.read()  # the initial state: its energy is the bound, as in a run never stopped
        stored = float(arrays.get("energy_start", math.nan))
        c2 = self.scene["fluid.stiffness"]
        if "energy_start" in arrays and not abs(stored - self.energy_start) <= 1e-3 * (
                abs(self.energy_start) + self.fluid_count * self.scene.mass * 1e-4 * c2):
            raise CheckpointError(f"checkpoint field energy_start = {stored:.6g} J is not the energy of the scene's "
                                  f"initial state, {self.energy_start:.6g} J: the checkpoint was altered")
        whole = CARRIED
        if keep is not None:
            total = self.scene.particle_count()
            for name in LOADED:
                if len(arrays[f"buffer_{name}"]) != total:
                    raise CheckpointError(f"checkpoint buffer {name} has {len(arrays[f'buffer_{name}'])} rows, this "
                                          f"scene {total} particles")
            self.load({name: arrays[f"buffer_{name}"][keep] for name in LOADED}, slab)
            whole = [name for name in CARRIED if name not in LOADED]
        current = self.backend.read(whole)
        for name in whole:
            values = arrays[f"buffer_{name}"]
            if values.shape != current[name].shape or values.dtype != current[name].dtype:
                raise CheckpointError(f"checkpoint buffer {name} is {values.dtype}{list(values.shape)}, this scene "
                                      f"needs {current[name].dtype}{list(current[name].shape)}")
            self.backend.write_buffer(name, values)
        if self.gauges is not None and "gauge_state" in arrays:
            state = np.asarray(arrays["gauge_state"])
            current = self.backend.read_buffer("gauge_state")
            if state.shape != current.shape or state.dtype != current.dtype or (state[::2] != current[::2]).any():
                raise CheckpointError(f"checkpoint field gauge_state ({state.dtype}{list(state.shape)}) is not of this "
                                      "scene's gauges")
            self.backend.write_buffer("gauge_state", state)
            self.gauges.taken, self.gauges.since, self.gauge_rows = state[1::2, 1].astype(np.int64), 0, []
        self.step_count = self.checked_step = int(arrays["step"])
        self._carried = None
        self.build_lists_next()
        self.solver.restore(arrays, self.step_count)

    def check_grid(self, status):
        """Raise SimulationError if the grid saw a particle outside its range (sphcore.health.check_grid)."""
        health.check_grid(self, status)

    def check(self, state):
        """Raise SimulationError at the first particle with a non-finite value or outside the box, or where
        the energy grew (sphcore.health.check_state)."""
        health.check_state(self, state)

    def check_energy(self, state):
        """Raise SimulationError where the energy or a particle's speed grew past its bound
        (sphcore.health.check_energy)."""
        health.check_energy(self, state)

    def close(self):
        """Free the backend's buffers (and the Vulkan device); every later use raises SimulationError
        (a second close does nothing). Refused while another thread uses the simulation."""
        if not self._lock.acquire(blocking=False):
            raise _in_use(self, "close")
        try:
            if not self._closed:
                self._closed = True
                self.backend.close()
        finally:
            self._lock.release()

    # -- the Python API (sphcore.Simulation): a run step by step, from a script or a notebook

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    @_exclusive
    def step(self, steps=1):
        """Run `steps` time steps on the backend (no readback: call read() for the state)."""
        if isinstance(steps, bool) or not isinstance(steps, (int, np.integer)) or steps < 0:
            raise ValueError(f"steps must be an integer >= 0, got {steps!r}")
        self.advance(int(steps))

    @_exclusive
    def write_snapshot(self, out_dir, state=None):
        """Write the current state (read() unless `state` is given) as a VTK snapshot
        out_dir/<name>_<step>.vtp and list it in out_dir/<name>.pvd (for ParaView); return its path.
        The folder is locked for the write, as a run locks it (sphcore.folder.RunFolder): refused
        (FolderError, naming the pid) while a run or another writer holds it."""
        state = self.read() if state is None else state
        with folder.RunFolder(out_dir) as run_folder:
            series = SnapshotSeries(out_dir, self.scene["name"], folder=run_folder)
            return series.add(self.step_count, self.time, state["particle_x"], {
                "velocity": state["particle_v"], "density": state["particle_rho"], "pressure": state["particle_p"]})

    @_exclusive
    def surface(self, spacing=None, level=0.5, backend=None, state=None):
        """The fluid's surface now (3D scenes): (verts, faces, normals) of the isosurface at `level`
        of the colour field, sampled every `spacing` (default h / 2), by marching cubes on `backend`
        (default: the simulation's); see sphcore.surface.particle_surface."""
        state = self.read() if state is None else state
        return particle_surface(self.scene, state["particle_x"], spacing=spacing, level=level,
                                backend=backend or self.backend.name)
