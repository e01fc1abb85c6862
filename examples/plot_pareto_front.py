"""
Speed against accuracy: the sweep's Pareto front
================================================

Which settings buy how much accuracy for how much time? ``sphcore sweep`` runs the 2D dam break
(Martin & Moyce 1952) at 49 points: a resolution ladder crossed with the model configurations, the
time step, the equation of state and the viscosity, each point's error the RMS of the front Z
against the experiment's Table 2, its cost the wall time spent stepping. Points no other point
beats in both are the Pareto front.

This example runs no simulation: it reads the measured table that ships with the repository,
``validation/results/sweep.json`` (written by ``sphcore sweep --out validation/results``, about
5 minutes on 2 cores), with the sweep's own functions (``sphcore.validate.sweep``), and draws the
front. It runs in about a second. A sweep of your own: ``sphcore sweep --out DIR`` (``--quick``
for a shorter one), then ``sphcore.validate.sweep.read_table(DIR)`` as below.
"""
from pathlib import Path

import matplotlib.pyplot as plt

from sphcore.validate import sweep

# %%
# Read the table: one row per point, its settings and its measured error and cost.
here = Path(__file__).resolve().parent if "__file__" in globals() else Path.cwd()
results = here.parent / "validation" / "results"
rows, meta = sweep.read_table(results)
ok = sweep.ok_rows(rows)
print(f"{len(rows)} points, {len(ok)} ran; measured {meta.get('started', '?')} on {meta.get('cpu_count', '?')} cores")

# %%
# The front, cheapest first, and the recommendation: the cheapest point within the threshold.
front = sweep.pareto_front(rows)
for r in front:
    print(f"{sweep.label(r):45s} error {r[sweep.ERROR]:.3f}  cost {r[sweep.COST]:.2f} s")
text = sweep.recommendations(rows)["text"]
print("\n".join((text if isinstance(text, list) else text.splitlines())[:3]))

# %%
# Draw every point, coloured by its model configuration, and the front as a staircase.
fig, ax = plt.subplots(figsize=(9, 5))
colours = plt.get_cmap("tab20").colors  # 20 distinct colours: one per configuration
for i, config in enumerate(dict.fromkeys(r["config"] for r in ok)):
    pts = [r for r in ok if r["config"] == config]
    ax.scatter([r[sweep.COST] for r in pts], [r[sweep.ERROR] for r in pts], s=30, label=config,
               color=colours[i % 20], edgecolor="k", linewidth=0.3)
ax.step([r[sweep.COST] for r in front], [r[sweep.ERROR] for r in front], "k-", where="post", lw=1.2,
        label="Pareto front", zorder=0)
ax.axhline(sweep.THRESHOLD, color="r", ls="--", lw=0.8, label=f"threshold RMS {sweep.THRESHOLD:g}")
ax.set(xscale="log", xlabel="cost: wall time stepping [s]", ylabel="error: RMS of Z against Table 2",
       title="2D dam break, validation/results/sweep.json")
ax.grid(True, which="both", lw=0.3, alpha=0.5)
ax.legend(fontsize=8, ncol=2)
fig.tight_layout()
plt.show()
