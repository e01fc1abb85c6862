"""Run a scene on a backend: step, check, write snapshots, checkpoints and the final state.

A run survives being stopped: every time.checkpoint_every steps (and at the start, at the end,
and where SIGINT or SIGTERM stops it) DIR/checkpoint.npz holds what `resume` needs to continue
to bitwise the same final state as a run that was never stopped, on the same backend and device.
Every file is written to a temporary name and renamed, so a reader (or a resume) never sees
half of one.
"""
import functools
import json
import math
import os
import re
import signal
import sys
import threading
import zipfile
from pathlib import Path

import numpy as np

from sphcore.backends import PARTICLE_BUFFERS, REUSE, empty_state, in_particle_order, make_backend, plan
from sphcore.scene import stable_dt
from sphcore.sph.dfsph import CONTROL_BUILDS, CONTROL_REBUILD
from sphcore.signals import HeldInterrupt, Signals
from sphcore.signals import Interrupted  # noqa: F401 (sphcore.simulation.Interrupted)


class SimulationError(RuntimeError):
    """The state became non-finite or left the box; the message names step, particle and likely cause.
    Also what a closed Simulation raises when it is used:

    >>> import sphcore
    >>> with sphcore.Simulation(sphcore.Scene.from_dict({"fluid": {"spacing": 0.05}})) as sim:
    ...     sim.step(10)
    >>> sim.read()
    Traceback (most recent call last):
    sphcore.simulation.SimulationError: Simulation.read(): this Simulation of 'scene' is closed ...
    """


class CheckpointError(SimulationError):
    """A run that cannot be resumed: no checkpoint, an unreadable one, or one that does not belong
    to the scene (or to this version's parameter block); the message names the file."""


CHECKPOINT = "checkpoint.npz"
# The buffers that carry the state from one step to the next (and the outputs of the last one);
# every other buffer is rewritten by each step before any stage reads it.
CARRIED = ("particle_x", "particle_v", "particle_a", "particle_rho", "particle_p", "particle_id", "grid_status",
           "particle_vh", "time_state",  # Verlet's half-step velocity; dt, the last dt and the time (adaptive dt)
           "control", "dfsph_state",  # DFSPH: its step count, unconverged solves, tolerances and errors,
           "particle_kappa")  # and its warm start
# What read() takes from the backend: the per-particle state, the grid's status and the carried buffers.
READ = tuple(dict.fromkeys((*PARTICLE_BUFFERS, "grid_status", *CARRIED)))


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
    arrays: particle_x, particle_v, particle_a (N, dim), particle_rho, particle_p (N,) and more;
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

    _carried = None  # the CARRIED buffers as the last read() saw them
    energy_start = None  # the energy at the first read, the bound for every later one
    _closed = False
    _user = None  # (thread name, method) of the call inside the simulation now (_exclusive)

    def __init__(self, scene, backend="numba", *, poll=None, **backend_options):
        """`poll()` is called between the start-up's stages (after each kernel is compiled): a safe
        point where sphcore.run stops on a signal. The host memory the run will need is checked
        first (sphcore.memory): a run that would not fit is refused before anything is allocated. The
        simulation keeps its own copy of `scene`, checked again (Scene.validated): a change made to the
        scene after it was loaded is checked, and one made later does not reach the run."""
        from sphcore import memory
        from sphcore.backends import check_options

        self._lock = threading.RLock()
        scene = scene.validated()
        check_options(backend, backend_options)
        memory.check(scene, backend)  # Vulkan: its device memory is checked once the device is known
        poll = poll or (lambda: None)
        if backend == "vulkan":  # lavapipe's device memory is host memory
            backend_options.setdefault("before_allocating",
                                       lambda ctx: memory.check(scene, backend, ctx.device_type == "CPU"))
        self.scene = scene
        x0 = scene.initial_positions()
        self.n, self.dim = len(x0), scene.dim
        self.params = scene.params(self.n)
        self.spec = scene.spec_for(backend)  # (neighbour lists with the state equation too, where they fit)
        state = empty_state(self.params, scene["physics.precision"], scene["domain.obstacles"],
                            self.spec.MAX_NEIGHBOURS, self.spec.GRADIENTS)
        state["particle_x"][:, :self.dim] = x0
        state["particle_rho"][:] = scene.initial_density(x0)  # the state's density where it is integrated (continuity)
        if scene.dfsph:
            from sphcore.pressure_solver import SolverLog, init_state
            init_state(state, scene)
            self.solver_log = SolverLog(scene)  # each step's iterations and errors (final.npz: solver_log)
        self.stages = plan(scene)
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
        for stage in self.stages:
            if stage.name not in ("compute_forces", "reduce_dt", "choose_dt", "integrate") and \
                    not stage.name.startswith("dfsph_") and stage.when != REUSE:
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
        DFSPH: its log is read at least every HISTORY_ROWS steps (sphcore.pressure_solver)."""
        from sphcore.sph.dfsph import HISTORY_ROWS

        chunk, collected, end = getattr(self.backend, "steps_per_submit", 1), self.step_count, self.step_count + steps
        with HeldInterrupt() as held:
            while self.step_count < end and held.received is None:
                k = min(chunk, end - self.step_count)
                if self.scene.dfsph:
                    k = min(k, HISTORY_ROWS - (self.step_count - collected))
                self.backend.step(k)
                self.step_count += k
                if self.scene.dfsph and (self.step_count - collected == HISTORY_ROWS or self.step_count == end
                                         or held.received is not None):
                    self.solver_log.collect(self.backend, collected, self.step_count)
                    collected = self.step_count
        if held.received is not None:
            raise KeyboardInterrupt(f"stopped after step {self.step_count} ({self.step_count - (end - steps)} of "
                                    f"the {steps} asked for)")

    @_exclusive
    def read(self):
        """The state in particle order (vectors of `dim` components), checked. A check that fails
        more than one step after the last good one is replayed from there a step at a time, so
        the error names the first step at which the state went wrong."""
        raw = self.backend.read(READ)  # (not the scratch, the grid or the neighbour lists: each step rewrites them)
        state = in_particle_order(raw, self.dim)
        try:
            self.check(state)
            self.check_grid(raw["grid_status"])
        except SimulationError:
            if self._carried is not None and self.step_count - self.checked_step > 1:
                self._replay()
            raise
        self.checked_step = self.step_count
        self._carried = {name: raw[name] for name in CARRIED}
        if self.energy_start is None:
            self.energy_start = sum(self.energy(state))
        self.build_lists_next()
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
        """(kinetic + potential from box_min, internal energy of the equation of state) [J; 2D: J/m].
        Nothing in the physics adds energy (walls and viscosity only take it away), so a run
        whose energy grows is blowing up. Internal energy: the integral of p / rho^2 d rho, from
        the densities of the last step (computed from the positions before it) or of the start."""
        scene = self.scene
        x, v = state["particle_x"].astype(np.float64), state["particle_v"].astype(np.float64)
        rho = state["particle_rho"].astype(np.float64)
        rho0, k = scene["fluid.rest_density"], scene["fluid.stiffness"]
        r = rho / rho0
        if scene["physics.density"] == "summation":
            r = np.maximum(r, 1.0)  # the pressure is clamped at 0 below rest density (not with continuity)
        if scene["physics.equation_of_state"] == "tait":
            internal = k / 7.0 * ((r ** 6 - 1.0) / 6.0 + 1.0 / r - 1.0)
        else:
            internal = k * (np.log(r) + 1.0 / r - 1.0)
        g = np.asarray(scene["forces.gravity"]) if scene["physics.gravity"] else np.zeros(self.dim)
        potential = -(x - np.asarray(scene["domain.box_min"])) @ g
        return float(scene.mass * (0.5 * (v * v).sum(axis=1) + potential).sum()), float(scene.mass * internal.sum())

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
        arrays = {f"buffer_{name}": values for name, values in self._carried.items()}
        # the parameter block as its bytes: numpy's .npy writer leaves a record's padding uninitialised
        arrays.update(energy_start=np.float64(self.energy_start), step=np.int64(self.step_count),
                      scene=np.array(self.scene.to_json()),
                      params=self.params.view(np.uint8), backend=np.array(self.backend.name), device=np.array(self.device_name))
        if self.scene.dfsph:  # each step's iterations and errors so far: a resumed run's log is whole
            arrays["solver_log"] = self.solver_log.array()
        return arrays

    @_exclusive
    def restore(self, arrays):
        """Continue from `arrays` (of `checkpoint()`, possibly on another backend): its buffers
        replace the backend's, its step becomes the step count. The energy bound is not taken
        from `arrays`: it is the energy of the scene's initial state, which the backend holds until
        the first restore (a stored energy_start that differs from it is refused)."""
        if self.energy_start is None:
            self.read()  # the initial state: its energy is the bound, as in a run never stopped
        stored = float(arrays.get("energy_start", math.nan))
        c2 = self.scene["fluid.stiffness"]
        if "energy_start" in arrays and not abs(stored - self.energy_start) <= 1e-3 * (
                abs(self.energy_start) + self.n * self.scene.mass * 1e-4 * c2):
            raise CheckpointError(f"checkpoint field energy_start = {stored:.6g} J is not the energy of the scene's "
                                  f"initial state, {self.energy_start:.6g} J: the checkpoint was altered")
        current = self.backend.read(CARRIED)
        for name in CARRIED:
            values = arrays[f"buffer_{name}"]
            if values.shape != current[name].shape or values.dtype != current[name].dtype:
                raise CheckpointError(f"checkpoint buffer {name} is {values.dtype}{list(values.shape)}, this scene "
                                      f"needs {current[name].dtype}{list(current[name].shape)}")
            self.backend.write_buffer(name, values)
        self.step_count = self.checked_step = int(arrays["step"])
        self._carried = None
        self.build_lists_next()
        if self.scene.dfsph and "solver_log" in arrays:  # (a replay's restore keeps the rows it has)
            self.solver_log.rows = {int(r[0]): np.array(r, np.float64) for r in arrays["solver_log"]
                                    if 0 < r[0] <= self.step_count}
            self.solver_log.reported = int(arrays["buffer_control"][6])  # CONTROL_FAILURES: reported then

    def check_grid(self, status):
        """Raise SimulationError if the grid saw a particle outside its range, or lost count of one."""
        steps = f"between steps {self.checked_step} and {self.step_count}"
        if status[0]:
            where = ("outside the box" if self.scene["domain.boundary"] == "walls"
                     else f"beyond the hashed range (+-2^24 cells of {self.scene.h:g} m)")
            raise SimulationError(f"{steps}: {int(status[0])} particle position(s) were {where} or not finite "
                                  f"(the first: particle {int(status[1])}); likely cause: a blow-up "
                                  f"(dt = {self.scene.dt:g} s, estimated bound {stable_dt(self.scene)[0]:.3g} s)")
        if status[2]:
            raise SimulationError(f"{steps}: the neighbour grid counted a different number of particles than "
                                  f"{self.n} in {int(status[2])} steps (a counter overflow): please report this")

    def check(self, state):
        """Raise SimulationError at the first particle with a non-finite value or outside the box."""
        for name, values in state.items():
            bad = ~np.isfinite(values.reshape(self.n, -1)).all(axis=1)
            if bad.any():
                i = int(np.argmax(bad))
                dt_max, bound = stable_dt(self.scene)
                dt = self.scene.dt
                cause = (f"time.dt = {dt:g} s exceeds the {bound} bound {dt_max:.3g} s" if dt > dt_max else
                         f"time.dt = {dt:g} s is within the estimated bound {dt_max:.3g} s ({bound}); "
                         "look for stiffness or viscosity at the ends of their ranges")
                if self.scene.dfsph:
                    cause = self.solver_log.diverged() or cause
                raise SimulationError(f"blow-up at step {self.step_count} (t = {self.time:.6g} s): {name} of "
                                      f"particle {i} is {values[i]} ({int(bad.sum())} particles non-finite); "
                                      f"likely cause: {cause}")
        self.check_energy(state)
        if self.scene["domain.boundary"] == "open":
            return
        x = state["particle_x"]
        # the walls as the shaders see them (float32): a particle clamped onto a wall sits exactly there
        lo = np.asarray(self.scene["domain.box_min"], np.float32)
        hi = np.asarray(self.scene["domain.box_max"], np.float32)
        outside = ((x < lo) | (x > hi)).any(axis=1)
        if outside.any():
            i = int(np.argmax(outside))
            raise SimulationError(f"step {self.step_count}: particle {i} at {x[i]} left the box {lo} .. {hi}")

    def check_energy(self, state):
        """Raise SimulationError if the energy grew past its start by 10 % (plus, per particle, the
        potential energy of a fall of h / 4 and the kinetic energy of 1 % of the sound
        speed), or a particle outruns twice the sound speed plus the free-fall speed (an explosion).
        The free-fall speed: from the top of the fluid to the floor, and in an open domain, where
        nothing stops a fall, also |g| t. The message says which of the two failed, with its figures."""
        scene = self.scene
        if self.energy_start is None or scene["physics.surface_tension"]:  # cohesion's energy is not counted
            return
        c = math.sqrt(scene["fluid.stiffness"])
        g = math.sqrt(sum(a * a for a in scene["forces.gravity"])) if scene["physics.gravity"] else 0.0
        allowed = (self.energy_start + 0.1 * abs(self.energy_start)
                   + self.n * scene.mass * (g * scene.h / 4 + 0.5 * (0.01 * c) ** 2))
        speed = np.sqrt((state["particle_v"].astype(np.float64) ** 2).sum(axis=1))
        fall = scene.speed_estimate() + (g * self.time if scene["domain.boundary"] == "open" else 0.0)
        limit = 2.0 * (c + fall)
        energy = sum(self.energy(state))
        if energy <= allowed and speed.max() <= limit:
            return
        i = int(np.argmax(speed))
        went = "rose" if energy > self.energy_start else "fell"
        if energy > allowed:
            what = (f"the energy rose from {self.energy_start:.4g} J to {energy:.4g} J, past the {allowed:.4g} J "
                    f"allowed, and particle {i} moves at {speed[i]:.3g} m/s (sound speed {c:.3g} m/s)")
        else:
            what = (f"particle {i} moves at {speed[i]:.3g} m/s, past the {limit:.3g} m/s allowed (twice the sound "
                    f"speed {c:.3g} m/s plus the free-fall speed {fall:.3g} m/s), while the energy {went} from "
                    f"{self.energy_start:.4g} J to {energy:.4g} J")
        dt_max, bound = stable_dt(scene, scene.speed_estimate())
        dt = scene.dt
        lo, hi = np.asarray(scene["domain.box_min"]), np.asarray(scene["domain.box_max"])
        gap = min((state["particle_x"][i] - lo).min(), (hi - state["particle_x"][i]).min())
        if dt > dt_max:
            cause = f"time.dt = {dt:g} s exceeds the {bound} bound {dt_max:.3g} s"
        elif not (scene["physics.viscosity"] and scene.shear_viscosity > 0):
            coefficient = "fluid.alpha" if scene["physics.viscosity_model"] == "artificial" else "fluid.viscosity"
            cause = f"no viscosity: nothing damps the particles' noise (raise {coefficient})"
        elif scene["domain.boundary"] == "walls" and gap < scene["fluid.spacing"] / 2:
            cause = (f"particle {i} is {gap:.3g} m from a wall, closer than half a spacing, where its mirror images "
                     "(the walls' ghost particles) push it; a particle that starts on a wall is pushed by images "
                     "that coincide with it: start the fluid at least fluid.spacing / 2 inside the box")
        elif energy > allowed:
            lower = "time.dt_fraction" if scene["time.dt"] == "auto" else "time.dt"
            cause = (f"dt = {dt:g} s is within the estimated {bound} bound {dt_max:.3g} s, yet the state gains "
                     f"energy: lower {lower} (a stiff fluid needs a fraction of the CFL bound)")
        else:
            cause = (f"one particle flung without the energy growing (dt = {dt:g} s is within the estimated {bound} "
                     f"bound {dt_max:.3g} s): a pair too close, or a force that is not the physics'; please report it")
        raise SimulationError(f"blow-up at step {self.step_count} (t = {self.time:.6g} s): {what}; "
                              f"likely cause: {cause}")

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
        from sphcore import folder
        from sphcore.output import SnapshotSeries

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
        from sphcore.surface import particle_surface

        state = self.read() if state is None else state
        return particle_surface(self.scene, state["particle_x"], spacing=spacing, level=level,
                                backend=backend or self.backend.name)


def final_arrays(sim, state):
    """The arrays of final.npz: state (position, velocity, density, pressure) and the parameters."""
    arrays = {
        "position": state["particle_x"],
        "velocity": state["particle_v"],
        "density": state["particle_rho"],
        "pressure": state["particle_p"],
        "step": np.int64(sim.step_count),
        "time": np.float64(sim.time),
        "dt": np.float64(sim.dt),
        "scene": np.array(sim.scene.to_json()),
        "mass": np.float64(sim.scene.mass),
        "h": np.float64(sim.scene.h),
    }
    for field in sim.params.dtype.names:
        arrays[f"param_{field}"] = np.asarray(sim.params[0][field])
    if sim.spec.LIST_SKIN:  # reused lists: their builds since the start (the start's own included)
        arrays["list_builds"] = np.int64(sim.backend.read_buffer("control")[CONTROL_BUILDS])
    if sim.scene.dfsph:  # DFSPH: each step's dt, time, iterations and final errors (sphcore.pressure_solver)
        from sphcore.pressure_solver import LOG_COLUMNS
        arrays["solver_log"] = sim.solver_log.array()
        arrays["solver_log_columns"] = np.array(LOG_COLUMNS)
    return arrays


def run(scene, backend="numba", steps=None, out_dir=None, progress=True, checkpoint=None, overwrite=False,
        **backend_options):
    """Run `scene` for `steps` steps in all, writing snapshots (VTK .vtp + .pvd), checkpoints and
    final.npz to `out_dir`; return the final arrays. `checkpoint`: arrays of load_checkpoint to
    start from (see `resume`).

    The run holds a lock on `out_dir` throughout (sphcore.folder): a second run into it is
    refused. A new run into a folder that holds a run is refused unless `overwrite`, which deletes
    that run's files first. A run that would not fit in memory is refused before it allocates
    (sphcore.memory); running out of memory all the same raises SimulationError, files kept.

    Snapshots go out every time.output_every steps and at the end; checkpoints at the start,
    every time.checkpoint_every steps and at the end. A blow-up raises SimulationError after
    the last good snapshot; SIGINT or SIGTERM raises Interrupted after a checkpoint at the step
    reached; a Vulkan failure raises VulkanError naming the checkpoint to resume from. Files
    already written are kept.

    >>> import os, tempfile, sphcore
    >>> out = tempfile.mkdtemp()
    >>> final = sphcore.run(sphcore.Scene.from_dict({"fluid": {"spacing": 0.05}}), steps=20, out_dir=out,
    ...                     progress=False)
    >>> int(final["step"]), final["position"].shape
    (20, (36, 2))
    >>> sorted(f for f in os.listdir(out) if not f.startswith("sphcore-"))
    ['checkpoint.npz', 'final.npz', 'scene.json', 'scene.pvd', 'scene_0000000.vtp', 'scene_0000020.vtp']
    """
    from tqdm import tqdm

    from sphcore import folder, memory
    from sphcore.output import SnapshotSeries
    from sphcore.vk_runner import VulkanError

    scene, steps, out_dir = _run_arguments(scene, backend, steps, out_dir, progress, checkpoint, overwrite,
                                           backend_options)  # each checked before the folder is touched
    memory.check(scene, backend)  # before the folder is touched (Simulation checks again, with the device)
    if checkpoint is not None and steps < int(checkpoint["step"]):
        raise CheckpointError(f"{out_dir / CHECKPOINT} is at step {int(checkpoint['step'])}, past the {steps} "
                              f"steps asked for: give --steps {int(checkpoint['step'])} or more")
    every, checkpoint_every = scene["time.output_every"], scene["time.checkpoint_every"]
    with Signals() as signals, folder.RunFolder(out_dir) as run_folder:  # locked; writes only its own files
        folder.remove_stale_temporaries(out_dir)
        run_folder.prepare(scene["name"], resume=checkpoint is not None, overwrite=overwrite)
        signals.poll()
        if checkpoint is None:
            run_folder.write_bytes("scene.json", scene.to_json().encode())  # what render and resume read
        try:
            series = SnapshotSeries(out_dir, scene["name"], folder=run_folder)
        except (SyntaxError, ValueError) as e:  # xml.etree's ParseError is a SyntaxError
            raise SimulationError(f"{out_dir / scene['name']}.pvd: not a readable ParaView collection ({e}); move "
                                  "it away, or write to another folder") from None
        try:
            sim = Simulation(scene, backend, poll=signals.poll, **backend_options)
        except VulkanError as e:
            raise _numba_hint(e, scene) from None
        except MemoryError as e:
            raise SimulationError(f"out of memory while starting the run ({e}); nothing to resume") from None
        signals.poll()
        saved = None  # the step of the last checkpoint written or resumed from

        def snapshot(state):
            series.add(sim.step_count, sim.time, state["particle_x"], {
                "velocity": state["particle_v"], "density": state["particle_rho"],
                "pressure": state["particle_p"]})

        def save_checkpoint():
            nonlocal saved
            run_folder.savez(CHECKPOINT, **sim.checkpoint())
            saved = sim.step_count

        try:
            if checkpoint is not None:
                sim.restore(checkpoint)
                saved = sim.step_count
                series.truncate(sim.step_count)  # snapshots past the checkpoint: of steps that will run again
                note_resume(checkpoint, sim, out_dir)
            state = sim.read()
            if checkpoint is None:
                snapshot(state)
                save_checkpoint()
            signals.stepping = True
            chunk = max(1, min(every, 50))
            with tqdm(total=steps, initial=sim.step_count, unit="step", disable=not progress,
                      desc=f"{scene['name']} [{backend}]") as bar:
                while sim.step_count < steps and not signals.received:
                    k = min(chunk, steps - sim.step_count, every - sim.step_count % every,
                            checkpoint_every - sim.step_count % checkpoint_every)
                    sim.advance(k)
                    sim.build_lists_next()  # (a step where the loop may stop, on a signal too: see there)
                    bar.update(k)
                    if sim.step_count % every == 0 or sim.step_count == steps:
                        state = None  # the previous state's arrays are freed before the next read
                        state = sim.read()
                        snapshot(state)
                    if sim.step_count % checkpoint_every == 0 or sim.step_count == steps or signals.received:
                        save_checkpoint()
                if signals.received and sim.step_count < steps:
                    if saved != sim.step_count:
                        save_checkpoint()
                    raise Interrupted(signals.received, f"interrupted by {signal.Signals(signals.received).name} "
                                      f"at step {sim.step_count} of {steps}; checkpoint written: continue "
                                      f"with `sphcore run --resume {out_dir}`")
            arrays = final_arrays(sim, state)
            run_folder.savez("final.npz", **arrays)
        except BaseException as e:
            _count_validation(sim)
            try:
                sim.close()
            except Exception:
                pass  # a lost device fails to close too: the first error is the one to report
            if isinstance(e, VulkanError) and saved is not None:
                cpu = " (add --backend numba to continue on the CPU)" if memory.fits(scene, "numba") else ""
                raise _numba_hint(VulkanError(f"{e}; the checkpoint at step {saved} is intact: continue with "
                                              f"`sphcore run --resume {out_dir}`{cpu}"), scene) from None
            if isinstance(e, MemoryError):
                kept = f"the checkpoint at step {saved} is intact" if saved is not None else "nothing to resume"
                raise SimulationError(f"out of memory at step {sim.step_count} ({e}); files written so far are "
                                      f"complete, {kept}") from None
            raise
        _count_validation(sim)
        sim.close()
        return arrays


def _run_arguments(scene, backend, steps, out_dir, progress, checkpoint, overwrite, backend_options):
    """run()'s arguments checked, before anything is deleted or written: (the scene checked again, a
    copy: Scene.validated; the steps; the folder). A bad one raises ValueError (SceneError for the
    scene) naming it."""
    from collections.abc import Mapping

    from sphcore.backends import check_options
    from sphcore.checkpoint import MAX_STEP
    from sphcore.scene import Scene

    if not isinstance(scene, Scene):
        raise ValueError(f"scene must be a sphcore.Scene (Scene.load or Scene.from_dict), got {type(scene).__name__}")
    scene = scene.validated()
    check_options(backend, backend_options)
    steps = scene["time.steps"] if steps is None else steps
    if isinstance(steps, bool) or not isinstance(steps, (int, np.integer)) or not 0 <= steps <= MAX_STEP:
        raise ValueError(f"steps must be an integer within [0, {MAX_STEP}] (the steps in all, counted from the run's "
                         f"start), got {steps!r}")
    if out_dir is not None and not isinstance(out_dir, (str, os.PathLike)):
        raise ValueError(f"out_dir must be a path (str or os.PathLike), got {type(out_dir).__name__}")
    for name, value in (("progress", progress), ("overwrite", overwrite)):
        if not isinstance(value, (bool, np.bool_)):
            raise ValueError(f"{name} must be True or False, got {value!r}")
    if checkpoint is not None and not (isinstance(checkpoint, Mapping) and "step" in checkpoint):
        raise ValueError("checkpoint must be the arrays of load_checkpoint (a mapping with a step), got "
                         f"{type(checkpoint).__name__}")
    return scene, int(steps), Path(out_dir or Path("runs") / scene["name"])


def _count_validation(sim):
    """With the Vulkan validation layers on, say how many errors they reported (each was printed as it came)."""
    ctx = getattr(sim.backend, "ctx", None)
    if getattr(ctx, "validation", False):
        count = len(ctx.validation_messages)
        print(f"sphcore: {count} Vulkan validation error(s){' (printed above)' if count else ''}", file=sys.stderr)


def _numba_hint(error, scene):
    """`error` (a VulkanError) with its "--backend numba" suggestion kept only where a numba run of
    `scene` would fit in memory; else the suggestion gives way to the figures."""
    from sphcore import memory
    from sphcore.vk_runner import VulkanError

    text = str(error)
    if "--backend numba" not in text:
        return error
    try:
        memory.check(scene, "numba")
        return error
    except memory.MemoryLimitError as e:
        text = re.sub(r",? or (run with )?--backend numba", "", text)
        return VulkanError(f"{text} (--backend numba would not fit either: {str(e).split(': ', 1)[1]})")


def load_checkpoint(out_dir):
    """(scene, checkpoint arrays) of the run in `out_dir`: the scene of out_dir/scene.json, which
    must be the one the checkpoint was computed with and give the same parameter block."""
    from sphcore import folder
    from sphcore.scene import Scene

    out_dir = Path(out_dir)
    path, scene_file = out_dir / CHECKPOINT, out_dir / "scene.json"
    if not path.is_file():
        raise CheckpointError(folder.missing_checkpoint(out_dir, CHECKPOINT))
    from sphcore.checkpoint import CheckpointFieldError, read_checked, read_scene
    from sphcore.scene import read_limited

    try:
        stored_scene = json.loads(read_scene(path))
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as e:  # JSONDecodeError is a ValueError
        raise CheckpointError(f"{path}: not a readable checkpoint ({e})") from None
    try:
        scene = Scene.from_dict(json.loads(read_limited(scene_file)), str(scene_file))
    except (OSError, ValueError) as e:  # SceneError, JSONDecodeError and UnicodeDecodeError are ValueErrors
        raise CheckpointError(f"{scene_file}: {getattr(e, 'strerror', None) or e}; the run's scene is needed "
                              "to resume") from None
    difference = _first_difference(scene.config, stored_scene)
    if difference:
        raise CheckpointError(f"{scene_file} is not the scene {path} was computed with ({difference}); "
                              "put the run's scene back, or start a new run in another folder")
    n = len(scene.initial_positions())
    try:
        arrays = read_checked(path, scene, scene.params(n), CARRIED)
    except CheckpointFieldError as e:
        raise CheckpointError(f"{path}: checkpoint {e}; refused") from None
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as e:
        raise CheckpointError(f"{path}: not a readable checkpoint ({e})") from None
    params = scene.params(n)
    if arrays["params"].tobytes() != params.tobytes():
        stored = np.frombuffer(arrays["params"].tobytes(), params.dtype) if arrays["params"].nbytes == params.nbytes else None
        field = "layout" if stored is None else next((f for f in params.dtype.names
                                                      if stored[0][f].tobytes() != params[0][f].tobytes()), "padding")
        raise CheckpointError(f"{path}: the parameter block this version of sphcore computes from the scene differs "
                              f"from the checkpoint's (field {field}): written by another version; "
                              "start a new run")
    return scene, arrays


def _first_difference(a, b, where=""):
    """'key: x here, y there' for the first dotted key whose values differ, else ''."""
    if isinstance(a, dict) and isinstance(b, dict):
        for name in sorted(set(a) | set(b)):
            found = _first_difference(a.get(name), b.get(name), f"{where}.{name}" if where else name)
            if found:
                return found
        return ""
    return "" if a == b else f"{where} = {json.dumps(a)} in scene.json, {json.dumps(b)} in the checkpoint"


def note_resume(checkpoint, sim, out_dir):
    """Say so on stderr where a resumed run continues on another backend or device than the one
    that wrote its checkpoint: it continues from the same state, but not to the same bits."""
    then = (str(checkpoint["backend"]), str(checkpoint["device"]))
    now = (sim.backend.name, sim.device_name)
    if then != now:
        print(f"sphcore: note: {out_dir}/{CHECKPOINT} was written by {then[0]} on {then[1]}; continuing on "
              f"{now[0]} on {now[1]}: the final state will not be bitwise that of an uninterrupted run",
              file=sys.stderr)


def resume(out_dir, backend=None, steps=None, progress=True, **backend_options):
    """Continue the run in `out_dir` from its checkpoint until it has `steps` steps in all (default:
    the scene's time.steps), on `backend` (default: the one that wrote the checkpoint). The
    snapshot series continues; with the same backend and device the final state is bitwise that
    of a run never stopped.

    >>> import tempfile, sphcore
    >>> out = tempfile.mkdtemp()
    >>> scene = sphcore.Scene.from_dict({"fluid": {"spacing": 0.05}})
    >>> _ = sphcore.run(scene, steps=20, out_dir=out, progress=False)
    >>> int(sphcore.resume(out, steps=40, progress=False)["step"])  # 20 steps more
    40
    """
    scene, checkpoint = load_checkpoint(out_dir)
    return run(scene, backend or str(checkpoint["backend"]), steps, out_dir, progress, checkpoint=checkpoint,
               **backend_options)
