"""Pictures of a state: particles coloured by speed (3D: seen from the front, along z)."""
from pathlib import Path

import numpy as np

from sphcore.output import atomic_savefig


def plot_state(npz_path, out=None):
    import json

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    data = np.load(npz_path, allow_pickle=False)
    scene = json.loads(str(data["scene"]))
    lo, hi = scene["domain"]["box_min"], scene["domain"]["box_max"]
    x, v = data["position"], data["velocity"]
    fig, ax = plt.subplots(figsize=(7, 7 * (hi[1] - lo[1]) / (hi[0] - lo[0]) + 0.6), dpi=120)
    order = np.argsort(x[:, 2]) if x.shape[1] == 3 else slice(None)  # nearest (largest z) drawn last
    dots = ax.scatter(x[order, 0], x[order, 1], c=np.linalg.norm(v, axis=1)[order], s=4 if x.shape[1] == 2 else 2,
                      cmap="viridis")
    ax.set(xlim=(lo[0], hi[0]), ylim=(lo[1], hi[1]), aspect="equal", xlabel="x [m]", ylabel="y [m]",
           title=f"{scene['name']}: {len(x)} particles, t = {float(data['time']):.3f} s")
    fig.colorbar(dots, ax=ax, label="speed [m/s]", shrink=0.8)
    out = Path(out or Path(npz_path).with_name("final.png"))
    atomic_savefig(fig, out, bbox_inches="tight")
    plt.close(fig)
    return out
