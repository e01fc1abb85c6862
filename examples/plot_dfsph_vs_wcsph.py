"""
DFSPH against weakly compressible SPH on the dam break
======================================================

The same 2D dam break (Martin & Moyce 1952; column a = 0.25 m wide, 2a high) run with two
pressure models: the weakly compressible state equation of the recommended "engineering"
configuration, whose time step is bound by the speed of sound, and divergence-free SPH (DFSPH,
Bender & Koschier 2015, 2017; the "dfsph" configuration), which solves for an incompressible
pressure each step and takes steps bound by the particle speed only. Both are compared with the
experiment's front (Table 2, shipped in ``validation/data``) and by the steps and time they take.

Here at 12 particles across a (288 particles): about 8 s for both on one core once numba has
compiled the two models' kernels (the first run: about 45 s). Run by hand at 25 (1,250
particles). The sweep (``sphcore sweep``) measures the same trade at more points: see the Pareto
example.
"""
import os
import time

import matplotlib.pyplot as plt
import numpy as np

import sphcore
from sphcore.validate import dam_break

SMALL = os.environ.get("SPHCORE_DOCS_SMALL") == "1"  # set by the docs build
resolution = 12 if SMALL else 25  # particles across the column's width a
a, t_end = 0.25, 0.4  # m, s


def front_curve(config):
    """(t, front x, steps, seconds stepping) of the dam break with the named configuration."""
    scene = dam_break.dam_break_scene({"resolution": resolution, "a": a, "config": config})
    k = dam_break.min_neighbours(scene)
    times, fronts, stepping = [], [], 0.0
    with sphcore.Simulation(scene, backend="numba") as sim:
        while sim.time < t_end:
            x = sim.read()["particle_x"]
            times.append(sim.time)
            fronts.append(dam_break.measure(scene, x, k)[0])
            start = time.perf_counter()
            sim.step(10)  # DFSPH's dt varies: read every 10 steps
            stepping += time.perf_counter() - start
        steps = sim.step_count
    return np.array(times), np.array(fronts), steps, stepping


# %%
# Run both. DFSPH's steps are longer (its dt follows the flow's speed: time.cfl_number), but
# each costs a few solver iterations; the state equation's are short and cheap.
curves = {}
for config in ("engineering", "dfsph"):
    curves[config] = front_curve(config)
    t, front, steps, seconds = curves[config]
    print(f"{config:12s} {steps:5d} steps, {seconds:5.2f} s stepping, front at {front[-1] / a:.2f} a")

# %%
# The fronts against the experiment (simulated time shifted by T = 0.175, as the validation
# does: the experiment's column was held by a membrane that took time to clear).
T_exp, Z_exp, _ = dam_break.read_series("table2")
fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(10, 3.8), gridspec_kw={"width_ratios": [1.6, 1]})
for config, (t, front, steps, seconds) in curves.items():
    T = t * np.sqrt(2 * dam_break.G / a) + dam_break.GATE_SHIFT
    ax0.plot(T, front / a, label=f"{config}: {steps} steps")
ax0.plot(T_exp, Z_exp, "ko", ms=4, label="Martin & Moyce 1952, Table 2")
ax0.set(xlabel="T = t sqrt(2g/a)", ylabel="Z = front / a", title=f"front, {resolution} particles across a")
ax0.legend(fontsize=8)
names = list(curves)
ax1.bar(names, [curves[c][3] for c in names], color=["C0", "C1"])
ax1.set(ylabel="seconds stepping (numba, 1 thread)", title="cost")
fig.tight_layout()
plt.show()
