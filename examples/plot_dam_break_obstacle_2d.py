"""
2D dam break against a cylinder: the force on a body
====================================================

A water column 0.4 m wide and 0.4 m high is released at t = 0 against the left wall of a closed
channel 1.6 m long; its front runs along the floor and hits a cylinder of radius 8 cm whose
lowest point is 4 cm above the floor (a pipe across the channel). The cylinder is a body given as
a polygon (``[[bodies]]``, a 32-gon: Adami et al. 2012's wall particles fill it), and a force gauge
(``[[gauges]]``, ``quantity = "force"``) records the fluid's force on it per metre of depth every
5 ms, on the device, with no read back per step (``Simulation.take_gauge_rows``). ``sphcore run``
writes the same gauge to ``RUN/gauges/F_pipe.csv``.

The engineering model. At 1 cm (1,600 fluid and 164 wall particles) its 2,720 steps to t = 0.8 s
took 26 s (18 s of CPU, 2 shared cores) once numba had compiled the model's kernels (the first run
does, for a few minutes; they are cached on disk); the docs build runs it at 2 cm (400 particles,
4 s).
"""
import os
import time

import matplotlib.pyplot as plt
import numpy as np

import sphcore

SMALL = os.environ.get("SPHCORE_DOCS_SMALL") == "1"  # set by the docs build
dx = 0.02 if SMALL else 0.01  # m
t_end = 0.8  # s
centre, radius = np.array([0.8, 0.12]), 0.08  # m: the cylinder, its lowest point 4 cm above the floor

# %%
# The scene: the channel, the column, the cylinder as a polygon (its vertices in order) and the force
# gauge on it. Everything else is the engineering model's default.
angles = np.linspace(0.0, 2 * np.pi, 32, endpoint=False)
polygon = (centre + radius * np.column_stack([np.cos(angles), np.sin(angles)])).tolist()
scene = sphcore.Scene.from_dict({
    "name": "dam_break_obstacle_2d",
    "physics": {"model": "engineering"},
    "domain": {"box_min": [0.0, 0.0], "box_max": [1.6, 0.6]},
    "fluid": {"blocks": [{"min": [0.0, 0.0], "max": [0.4, 0.4]}], "spacing": dx,
              "stiffness": 900.0},  # m^2/s^2: c = 30 m/s, about 10x the front speed 2 sqrt(g 0.4 m)
    "bodies": [{"name": "pipe", "polygon": polygon}],
    "gauges": [{"name": "F_pipe", "quantity": "force", "body": "pipe", "interval": 0.005}],
    "time": {"end": t_end},
})
walls, _ = scene.wall_positions()
print(f"{len(scene.initial_positions())} fluid particles, {len(walls)} wall particles, dx = {dx} m")

# %%
# Step to the end, keeping the state at t = 0.4 s (the flow around the cylinder) for the picture.
start = time.perf_counter()
with sphcore.Simulation(scene, backend="numba") as sim:
    while sim.time < 0.4:
        sim.step(20)
    picture, t_picture = sim.read(), sim.time
    while sim.time < t_end:
        sim.step(100)
    (force,) = sim.take_gauge_rows()  # time [s], Fx [N/m], Fy [N/m]
print(f"{sim.step_count} steps in {time.perf_counter() - start:.1f} s; {len(force)} force samples")

# %%
# The flow at t = 0.4 s and the force over time, each sample (thin) and its running mean over 25 ms:
# the push along the channel (Fx) from the impact at about 0.22 s on, and the vertical force (Fy),
# whose spikes come as the water closes over the cylinder and strikes it from above.
fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(11, 3.6), gridspec_kw={"width_ratios": [1.6, 1]})
x, v = picture["particle_x"], np.linalg.norm(picture["particle_v"], axis=1)
dots = ax0.scatter(x[:, 0], x[:, 1], c=v, s=4 if SMALL else 2, cmap="viridis")
ax0.add_patch(plt.Polygon(polygon, color="0.6"))
ax0.set(xlim=(0, 1.6), ylim=(0, 0.6), aspect="equal", xlabel="x [m]", ylabel="y [m]", title=f"t = {t_picture:.2f} s")
fig.colorbar(dots, ax=ax0, label="speed [m/s]")
for k, (label, colour) in enumerate((("Fx", "C0"), ("Fy", "C1")), start=1):
    ax1.plot(force[:, 0], force[:, k], color=colour, lw=0.5, alpha=0.5)
    ax1.plot(force[:, 0], np.convolve(force[:, k], np.ones(5) / 5, mode="same"), color=colour, label=label)
ax1.set(xlabel="t [s]", ylabel="force [N/m]", title="the fluid's force on the cylinder")
ax1.legend(fontsize=8)
fig.tight_layout()
plt.show()
