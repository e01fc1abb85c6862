"""Run a scene on a backend: step, check, write snapshots and the final state."""
from pathlib import Path

import numpy as np

from sphcore.backends import empty_state, in_particle_order, make_backend, plan
from sphcore.scene import stable_dt


class SimulationError(RuntimeError):
    """The state became non-finite or left the box; the message names step, particle and likely cause."""


class Simulation:
    """A scene's particles on one backend. `advance(k)` runs k steps; `read()` checks and returns the state."""

    def __init__(self, scene, backend="numba", **backend_options):
        self.scene = scene
        x0 = scene.initial_positions()
        self.n, self.dim = len(x0), scene.dim
        self.params = scene.params(self.n)
        state = empty_state(self.params)
        state["particle_x"][:, :self.dim] = x0
        self.stages = plan(scene)
        self.backend = make_backend(backend, self.params, state, self.stages, scene.spec, **backend_options)
        self.step_count = 0
        self.checked_step = 0

    @property
    def time(self):
        return self.step_count * float(self.params[0]["dt"])

    def advance(self, steps):
        self.backend.step(steps)
        self.step_count += steps

    def read(self):
        """The state in particle order (vectors of `dim` components), checked."""
        raw = self.backend.read()
        state = in_particle_order(raw, self.dim)
        self.check(state)
        self.check_grid(raw["grid_status"])
        self.checked_step = self.step_count
        return state

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
                raise SimulationError(f"blow-up by step {self.step_count} (t = {self.time:.6g} s): {name} of "
                                      f"particle {i} is {values[i]} ({int(bad.sum())} particles non-finite); "
                                      f"likely cause: {cause}")
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

    def close(self):
        self.backend.close()


def final_arrays(sim, state):
    """The arrays of final.npz: state (position, velocity, density, pressure) and the parameters."""
    arrays = {
        "position": state["particle_x"],
        "velocity": state["particle_v"],
        "density": state["particle_rho"],
        "pressure": state["particle_p"],
        "step": np.int64(sim.step_count),
        "time": np.float64(sim.time),
        "scene": np.array(sim.scene.to_json()),
        "mass": np.float64(sim.scene.mass),
        "h": np.float64(sim.scene.h),
    }
    for field in sim.params.dtype.names:
        arrays[f"param_{field}"] = np.asarray(sim.params[0][field])
    return arrays


def run(scene, backend="numba", steps=None, out_dir=None, progress=True, **backend_options):
    """Run `scene`, writing snapshots (VTK .vtp + .pvd) and final.npz to `out_dir`; return final arrays.

    Snapshots go out every time.output_every steps and at the end. A blow-up raises
    SimulationError after the last good snapshot; files already written are kept.
    """
    from tqdm import tqdm

    from sphcore.output import SnapshotSeries, atomic_savez, atomic_write_bytes

    steps = scene["time.steps"] if steps is None else steps
    out_dir = Path(out_dir or Path("runs") / scene["name"])
    out_dir.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(out_dir / "scene.json", scene.to_json().encode())  # what `sphcore render` reads
    series = SnapshotSeries(out_dir, scene["name"])
    every = scene["time.output_every"]
    sim = Simulation(scene, backend, **backend_options)
    try:
        def snapshot(state):
            series.add(sim.step_count, sim.time, state["particle_x"], {
                "velocity": state["particle_v"], "density": state["particle_rho"],
                "pressure": state["particle_p"]})

        state = sim.read()
        snapshot(state)
        chunk = max(1, min(every, 50))
        with tqdm(total=steps, unit="step", disable=not progress, desc=f"{scene['name']} [{backend}]") as bar:
            while sim.step_count < steps:
                k = min(chunk, steps - sim.step_count, every - sim.step_count % every)
                sim.advance(k)
                bar.update(k)
                if sim.step_count % every == 0 or sim.step_count == steps:
                    state = sim.read()
                    snapshot(state)
        arrays = final_arrays(sim, state)
        atomic_savez(out_dir / "final.npz", **arrays)
        return arrays
    finally:
        sim.close()
