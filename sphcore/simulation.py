"""Run a scene on a backend: step, check, write snapshots and the final state."""
import math
from pathlib import Path

import numpy as np

from sphcore.backends import empty_state, make_backend, plan


class SimulationError(RuntimeError):
    """The state became non-finite or left the box; the message names step, particle and likely cause."""


def stable_dt(scene, max_speed=0.0):
    """Largest stable time step [s] and the bound that sets it.

    CFL: 0.25 h / (c + |v|max), c = sqrt(k); viscous: 0.125 h^2 rho_0 / mu; body force:
    0.25 sqrt(h / |g|) (Monaghan 1992; Morris et al. 1997).
    """
    h = scene.h
    bounds = {"CFL": 0.25 * h / (math.sqrt(scene["fluid.stiffness"]) + max_speed)}
    if scene["fluid.viscosity"] > 0:
        bounds["viscous"] = 0.125 * h * h * scene["fluid.rest_density"] / scene["fluid.viscosity"]
    g = math.hypot(*scene["forces.gravity"])
    if g > 0:
        bounds["force"] = 0.25 * math.sqrt(h / g)
    name = min(bounds, key=bounds.get)
    return bounds[name], name


class Simulation:
    """A scene's particles on one backend. `advance(k)` runs k steps; `read()` checks and returns the state."""

    def __init__(self, scene, backend="numba", **backend_options):
        self.scene = scene
        x0 = scene.initial_positions()
        self.n = len(x0)
        state = empty_state(self.n)
        state["particle_x"][:] = x0
        self.params = scene.params(self.n)
        self.stages = plan(scene)
        self.backend = make_backend(backend, self.params, state, self.stages, **backend_options)
        self.step_count = 0

    @property
    def time(self):
        return self.step_count * float(self.params[0]["dt"])

    def advance(self, steps):
        self.backend.step(steps)
        self.step_count += steps

    def read(self):
        state = self.backend.read()
        self.check(state)
        return state

    def check(self, state):
        """Raise SimulationError at the first particle with a non-finite value or outside the box."""
        for name, values in state.items():
            bad = ~np.isfinite(values.reshape(self.n, -1)).all(axis=1)
            if bad.any():
                i = int(np.argmax(bad))
                dt_max, bound = stable_dt(self.scene)
                dt = self.scene["time.dt"]
                cause = (f"time.dt = {dt:g} s exceeds the {bound} bound {dt_max:.3g} s" if dt > dt_max else
                         f"time.dt = {dt:g} s is within the estimated bound {dt_max:.3g} s ({bound}); "
                         "look for stiffness or viscosity at the ends of their ranges")
                raise SimulationError(f"blow-up by step {self.step_count} (t = {self.time:.6g} s): {name} of "
                                      f"particle {i} is {values[i]} ({int(bad.sum())} particles non-finite); "
                                      f"likely cause: {cause}")
        x = state["particle_x"]
        lo, hi = np.asarray(self.scene["domain.box_min"]), np.asarray(self.scene["domain.box_max"])
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

    from sphcore.output import SnapshotSeries, atomic_savez

    steps = scene["time.steps"] if steps is None else steps
    out_dir = Path(out_dir or Path("runs") / scene["name"])
    out_dir.mkdir(parents=True, exist_ok=True)
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
