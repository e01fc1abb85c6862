"""
2D dam break against Martin & Moyce (1952)
==========================================

A water column of width a = 0.25 m and height 2a is released at t = 0 against the left wall of a
closed channel and collapses; its front runs along the floor. The front position, made
dimensionless as in the experiment (Z = x / a against T = t sqrt(2 g / a)), is compared with
Martin & Moyce's measurements (1952, Table 2, shipped in ``validation/data``).

The scene is the one ``sphcore validate dam-break`` builds (``sphcore.validate.dam_break``), with
the recommended "engineering" model. Here at 12 particles across a (288 particles): about 3 s on
one core once numba has compiled the model's kernels, which the first run does (about 20 s; they
are cached on disk). Run by hand it takes 25 particles across a (1,250 particles, several times
longer): the resolution of the validation's most accurate point.
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

# %%
# The scene: the validation case's, with the recommended model's keys laid over it
# (``sphcore.validate.configs.CONFIGS["engineering"]``; the Scenes page lists them).
scene = dam_break.dam_break_scene({"resolution": resolution, "a": a, "config": "engineering"})
print(f"{len(scene.initial_positions())} particles, dx = {scene['fluid.spacing']:.4f} m, dt = {scene.dt:.2e} s")

# %%
# Step it, reading the state back every 0.02 s to measure the front: the furthest particle with
# enough neighbours (spray ahead of the surge does not count), plus half a spacing.
k = dam_break.min_neighbours(scene)
every = max(1, round(0.02 / scene.dt))
times, fronts = [], []
start = time.perf_counter()
with sphcore.Simulation(scene, backend="numba") as sim:
    while sim.time < t_end:
        state = sim.read()
        front, _ = dam_break.measure(scene, state["particle_x"], k)
        times.append(sim.time)
        fronts.append(front)
        sim.step(every)
    state, t_final, steps = sim.read(), sim.time, sim.step_count
print(f"{steps} steps in {time.perf_counter() - start:.1f} s")

# %%
# Draw the final state and the front against the experiment. Simulations released at once lead
# the experiment, whose column was held by a membrane that took time to clear: the validation
# shifts simulated time by T = 0.175 (``dam_break.GATE_SHIFT``), as done here.
T = np.array(times) * np.sqrt(2 * dam_break.G / a) + dam_break.GATE_SHIFT
Z = np.array(fronts) / a
T_exp, Z_exp, _ = dam_break.read_series("table2")

fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(11, 3.6), gridspec_kw={"width_ratios": [1.6, 1]})
x, v = state["particle_x"], np.linalg.norm(state["particle_v"], axis=1)
dots = ax0.scatter(x[:, 0], x[:, 1], c=v, s=6, cmap="viridis")
ax0.set(xlim=(0, scene["domain.box_max"][0]), ylim=(0, scene["domain.box_max"][1]), aspect="equal",
        xlabel="x [m]", ylabel="y [m]", title=f"t = {t_final:.2f} s")
fig.colorbar(dots, ax=ax0, label="speed [m/s]")
ax1.plot(T, Z, "-", label=f"sphcore, {resolution} particles across a")
ax1.plot(T_exp, Z_exp, "ko", ms=4, label="Martin & Moyce 1952, Table 2")
ax1.set(xlabel="T = t sqrt(2g/a)", ylabel="Z = front / a", title="front")
ax1.legend(fontsize=8)
fig.tight_layout()
plt.show()
