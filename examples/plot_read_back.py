"""
Reading a run back for analysis
===============================

What a run leaves on disk and how to read it: ``sphcore.run`` (what ``sphcore run`` calls) writes a
folder with ``final.npz`` (the final state and the scene), a snapshot ``NAME_<step>.vtp`` every
``time.output_every`` steps listed with its time in ``NAME.pvd`` (ParaView's collection), and
checkpoints. Here a small 2D dam break (Martin & Moyce 1952's column, the "engineering" model) is
run into a temporary folder, and read back three ways: ``final.npz`` with numpy, the ``.pvd``'s
list of snapshots with ``sphcore.SnapshotSeries``, and each snapshot's particle data with pyvista.

Here at 12 particles across the column (288 particles): about 3 s on one core once numba has
compiled the model's kernels (the first run: about 20 s). Run by hand at 25.
"""
import copy
import json
import os
import tempfile

import matplotlib.pyplot as plt
import numpy as np
import pyvista as pv

import sphcore
from sphcore.validate import dam_break

SMALL = os.environ.get("SPHCORE_DOCS_SMALL") == "1"  # set by the docs build
resolution = 12 if SMALL else 25

# %%
# A run of 0.4 s into a temporary folder, a snapshot every 0.02 s.
scene = dam_break.dam_break_scene({"resolution": resolution, "config": "engineering"})
config = copy.deepcopy(scene.config)
every = max(1, round(0.02 / scene.dt))
config["time"].update(steps=every * 20, output_every=every)
scene = sphcore.Scene.from_dict(config)
out = tempfile.mkdtemp(prefix="sphcore_read_back_")
sphcore.run(scene, out_dir=out, progress=False)
print(sorted(os.listdir(out))[:6], "...")

# %%
# ``final.npz``: position, velocity, density, pressure, step, time, the scene as JSON and the
# folded parameters (``param_*``).
with np.load(f"{out}/final.npz") as final:
    x, p = final["position"], final["pressure"]
    t_final = float(final["time"])
    name = json.loads(str(final["scene"]))["name"]
print(f"{name}: {len(x)} particles at t = {t_final:.3f} s, pressure up to {p.max():.0f} Pa")

# %%
# The snapshots, in step order, as the ``.pvd`` lists them; pyvista reads each ``.vtp`` (point
# data: velocity, density, pressure). From them, the kinetic energy and the density's spread
# over time.
series = sphcore.SnapshotSeries(out, name)
mass = scene.mass
times, energy, spread = [], [], []
reader = pv.get_reader(str(series.pvd_path))
for t in reader.time_values:
    reader.set_active_time_value(t)
    snap = reader.read()[0]
    v = np.asarray(snap.point_data["velocity"])
    rho = np.asarray(snap.point_data["density"])
    times.append(t)
    energy.append(0.5 * mass * (v ** 2).sum())
    spread.append(rho.std() / rho.mean())
print(f"{len(series.files)} snapshots, {series.files[0].name} ... {series.files[-1].name}")

# %%
# Draw the final pressure field and the histories.
fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(11, 3.6), gridspec_kw={"width_ratios": [1.6, 1]})
dots = ax0.scatter(x[:, 0], x[:, 1], c=p, s=6, cmap="plasma")
ax0.set(xlim=(0, scene["domain.box_max"][0]), ylim=(0, scene["domain.box_max"][1]), aspect="equal",
        xlabel="x [m]", ylabel="y [m]", title=f"final.npz: pressure at t = {t_final:.2f} s")
fig.colorbar(dots, ax=ax0, label="pressure [Pa]")
ax1.plot(times, energy, "C0-o", ms=3)
ax1.set(xlabel="t [s]", ylabel="kinetic energy [J per m depth]", title="from the .pvd's snapshots")
ax2 = ax1.twinx()
ax2.plot(times, np.array(spread) * 100, "C1--", lw=1)
ax2.set_ylabel("density spread [%]", color="C1")
fig.tight_layout()
plt.show()
