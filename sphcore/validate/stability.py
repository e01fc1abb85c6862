"""The stability matrix: scenes at the extremes of every parameter, each run until it ends
either stable (finite, energy bounded, every particle inside the box) or detected (the run
stopped at the first non-finite or exploding value, naming the step, the particle and the likely
cause, with the snapshots written before it kept).

`sphcore validate stability --out DIR` runs the matrix into DIR/<case>/ and writes
DIR/stability.json and DIR/stability.csv.
"""
import csv
import io
import json
import math
import re
from pathlib import Path

import numpy as np

from sphcore.scene import Scene, stable_dt

BOX = {"box_min": [0.0, 0.0], "box_max": [0.4, 0.4]}
COLUMN = [{"min": [0.0, 0.0], "max": [0.1, 0.2]}]  # 5 x 10 particles at dx = 0.02
STEPS_SECONDS = 0.2  # simulated time of each case
MAX_STEPS = 1500  # or this many steps, where the time step is small


def scene(name, physics=None, fluid=None, time=None, gravity=None, blocks=COLUMN):
    return Scene.from_dict({
        "name": name, "physics": {"model": "graphics", **(physics or {})}, "domain": BOX,
        "fluid": {"blocks": blocks, "spacing": 0.02, "stiffness": 400.0, "viscosity": 1.0, **(fluid or {})},
        "forces": {"gravity": gravity or [0.0, -9.81]},
        "time": {"dt": "auto", "steps": 1, "output_every": 100, "checkpoint_every": 1000, **(time or {})},
    }, source=f"stability case {name}")


def corner_positions(s):
    """Particles exactly on the four walls and in the four corners of the box."""
    (x0, y0), (x1, y1) = s["domain.box_min"], s["domain.box_max"]
    xm, ym = (x0 + x1) / 2, (y0 + y1) / 2
    return np.array([[x0, y0], [x1, y0], [x0, y1], [x1, y1], [xm, y0], [xm, y1], [x0, ym], [x1, ym]])


# name -> (scene, initial positions or None (the scene's lattice), the outcome measured and explained:
# "stable" | "detected"). Past 10x the CFL bound the particles overshoot each other; without
# viscosity the particle noise grows (the column turns to gas); a particle on a wall coincides
# with its own mirror images, whose full-kernel pressure throws it off faster than energy allows.
def stacked(copies):
    """Initial positions: `copies` copies of the first block's lattice on top of each other (a scene
    refuses overlapping blocks, so such a case is given side-by-side blocks and moved here)."""
    def positions(s):
        x = s.initial_positions()
        return np.tile(x[:len(x) // copies], (copies, 1))
    return positions


def cases():
    one = [{"min": [0.2, 0.3], "max": [0.22, 0.32]}]
    beside = [{"min": [0.22, 0.3], "max": [0.24, 0.32]}]
    cell = [{"min": [x, y], "max": [x + 0.08, y + 0.08]} for x, y in ((0.16, 0.16), (0.08, 0.16), (0.16, 0.08), (0.08, 0.08))]
    return {
        "dt_at_bound": (scene("dt_at_bound", time={"dt_fraction": 1.0}), None, "stable"),
        "dt_10x_bound": (scene("dt_10x_bound", time={"dt_fraction": 10.0}), None, "detected"),
        "stiffness_1e5": (scene("stiffness_1e5", fluid={"stiffness": 1e5}), None, "stable"),
        "stiffness_1": (scene("stiffness_1", fluid={"stiffness": 1.0}), None, "stable"),
        "viscosity_0": (scene("viscosity_0", fluid={"viscosity": 0.0}), None, "detected"),
        "viscosity_1e4": (scene("viscosity_1e4", fluid={"viscosity": 1e4}), None, "stable"),
        "zero_gravity": (scene("zero_gravity", physics={"gravity": False}), None, "stable"),
        "one_particle": (scene("one_particle", blocks=one), None, "stable"),
        "two_coincident": (scene("two_coincident", blocks=one + beside), stacked(2), "stable"),
        "one_cell": (scene("one_cell", fluid={"smoothing_ratio": 6.0}, blocks=cell), stacked(4), "stable"),
        "walls_and_corners": (scene("walls_and_corners", blocks=[{"min": [0.0, 0.0], "max": [0.16, 0.02]}]),
                              corner_positions, "detected"),
    }


def bytes_per_particle(precision="float32"):
    """Device (or host) memory one particle takes in the solver's buffers [bytes]."""
    from sphcore.backends import BUFFERS, REAL

    real = 8 if precision == "float64" else 4
    return sum((real if dtype == REAL else np.dtype(dtype).itemsize) * c
               for dtype, c, length in BUFFERS.values() if length == "particles")


def largest_count(backend="numba", precision="float32", device=None):
    """(count, what sets it): the most particles the backend's memory allows, capped by the
    scene's MAX_PARTICLES. Vulkan: the largest storage buffer (4 reals per particle) and 80 % of
    the largest device-local heap; numba: half the host memory available now."""
    import os

    from sphcore.scene import MAX_PARTICLES

    per = bytes_per_particle(precision)
    real = 8 if precision == "float64" else 4
    limits = {"the scene limit MAX_PARTICLES": MAX_PARTICLES}
    if backend == "vulkan":
        from sphcore.vk_runner import Context

        ctx = Context(device=device)
        try:
            limits[f"the largest storage buffer of {ctx.device_name}"] = ctx.max_storage_buffer_range // (4 * real)
            mp = ctx.memory_properties
            heap = max(mp.memoryHeaps[i].size for i in range(mp.memoryHeapCount) if mp.memoryHeaps[i].flags & 1)
            limits[f"80 % of {ctx.device_name}'s {heap / 2**30:.0f} GiB"] = int(0.8 * heap / per)
        finally:
            ctx.close()
    else:
        free = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
        limits[f"half the host's {free / 2**30:.0f} GiB available"] = int(0.5 * free / per)
    name = min(limits, key=limits.get)
    return limits[name], name


def largest_scene(count, precision="float32"):
    """A 3D cube of (at most) `count` particles resting on the floor of a box 1.5 times as wide."""
    side = int(round(count ** (1 / 3)))
    while side ** 3 > count:
        side -= 1
    dx = 0.01
    edge = side * dx
    return Scene.from_dict({
        "name": "largest_count", "physics": {"model": "graphics", "dimension": 3, "precision": precision},
        "domain": {"box_min": [0.0, 0.0, 0.0], "box_max": [1.5 * edge, 1.5 * edge, 1.5 * edge]},
        "fluid": {"blocks": [{"min": [0.0, 0.0, 0.0], "max": [edge + 1e-9, edge + 1e-9, edge + 1e-9]}],
                  "spacing": dx, "stiffness": 400.0, "viscosity": 1.0},
        "forces": {"gravity": [0.0, -9.81, 0.0]},
        "time": {"dt": "auto", "steps": 1},
    }, source="stability case largest_count")


def speed_limit(s):
    """The speed past which Simulation.check_energy calls a run exploding [m/s]."""
    return 2.0 * (math.sqrt(s["fluid.stiffness"]) + s.speed_estimate())


def place(sim, x):
    """Start `sim` from positions `x` (N, dim) in place of its scene's lattice."""
    arrays = sim.checkpoint()
    arrays["buffer_particle_x"][:, :sim.dim] = x
    del arrays["energy_start"]
    sim.restore(arrays)
    sim.compute_densities()
    sim.energy_start = None  # a new start: its energy bounds the run (restore took the lattice's)


def run_case(name, s, positions, out_dir, backend="numba", steps=None, snapshots=True, **options):
    """Run case `name` for STEPS_SECONDS (at most MAX_STEPS); return its row: status stable (every
    check of Simulation.read passed: finite, inside the box, energy and speed bounded) or detected."""
    from sphcore.simulation import Simulation, SimulationError
    from sphcore.output import SnapshotSeries

    out = Path(out_dir) / name
    out.mkdir(parents=True, exist_ok=True)
    series = SnapshotSeries(out, name)
    add = series.add if snapshots else lambda *args: None
    steps = steps or max(1, min(MAX_STEPS, math.ceil(STEPS_SECONDS / s.dt)))
    every = max(1, steps // 10)
    sim = Simulation(s, backend, **options)
    row = {"case": name, "particles": sim.n, "dt": s.dt, "dt_bound": stable_dt(s, s.speed_estimate())[0],
           "steps": steps, "status": "stable", "step": "", "particle": "", "cause": "", "message": ""}
    try:
        if positions is not None:
            place(sim, positions(s))
        state = sim.read()
        e_max, v_max = 0.0, 0.0
        add(0, 0.0, state["particle_x"], {"velocity": state["particle_v"]})
        while sim.step_count < steps:
            sim.advance(min(every, steps - sim.step_count))
            state = sim.read()
            add(sim.step_count, sim.time, state["particle_x"], {"velocity": state["particle_v"]})
            e_max = max(e_max, sum(sim.energy(state)))
            v_max = max(v_max, float(np.sqrt((state["particle_v"].astype(np.float64) ** 2).sum(axis=1)).max()))
        row.update(energy_start=sim.energy_start, energy_max=e_max, speed_max=v_max, speed_limit=speed_limit(s), time=sim.time)
    except SimulationError as e:
        message = str(e)
        m = re.search(r"step (\d+)", message)
        p = re.search(r"particle (\d+)", message)
        c = re.search(r"likely cause: (.*)", message)
        row.update(status="detected", step=int(m.group(1)) if m else "", particle=int(p.group(1)) if p else "",
                   cause=c.group(1) if c else "", message=message)
    finally:
        sim.close()
    row["snapshots"] = len(series.files)
    return row


def run_matrix(out_dir, backend="numba", progress=True, only=None, largest=False, **options):
    """Run every case (or those named in `only`), and with `largest` the largest particle count the
    backend's memory allows for 20 steps; write stability.json and stability.csv; return the rows."""
    from tqdm import tqdm

    from sphcore.output import atomic_write_bytes

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    todo = {k: v for k, v in cases().items() if only is None or k in only}
    for name, (s, positions, expected) in tqdm(todo.items(), desc="stability matrix", disable=not progress):
        row = run_case(name, s, positions, out, backend, **options)
        row["expected"] = expected
        rows.append(row)
        atomic_write_bytes(out / "stability.json", json.dumps(rows, indent=1).encode())
    if largest:
        count, limit = largest_count(backend, device=options.get("device"))
        s = largest_scene(count)
        row = run_case("largest_count", s, None, out, backend, steps=20, snapshots=False, **options)
        row.update(expected="stable", limit=f"{count} particles allowed by {limit}")
        rows.append(row)
        atomic_write_bytes(out / "stability.json", json.dumps(rows, indent=1).encode())
    buf = io.StringIO()
    fields = sorted({k for r in rows for k in r}, key=lambda k: list(rows[0]).index(k) if k in rows[0] else 99)
    writer = csv.DictWriter(buf, fieldnames=fields, lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    atomic_write_bytes(out / "stability.csv", buf.getvalue().encode())
    return rows
