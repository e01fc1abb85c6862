"""Plot marching-cubes extraction time against cube count from marching_cubes.py JSON files.

    python benchmarks/plot_marching_cubes.py benchmarks/results/mc_h200.json \
        benchmarks/results/mc_cpu.json --out benchmarks/results/marching_cubes.png

One line per contender and method found in the files (each file's machine in the legend),
seed 2's GTX 560 figures dashed, and the 0.25 and 0.08 ms targets at 163x323x163 marked. Log-log axes.
"""
import argparse
import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

LABELS = {("vulkan", "histopyramid"): "HistoPyramid, indirect", ("vulkan", "histopyramid_readback"): "HistoPyramid, readback",
          ("vulkan", "per_cube"): "per cube, an atomic per subgroup", ("numba", "histopyramid"): "numba HistoPyramid",
          ("numba", "per_cube"): "numba per cube (sequential)", ("skimage", "lewiner"): "scikit-image (Lewiner)",
          ("vtk", "flying_edges"): "VTK flying edges"}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("files", nargs="+", type=Path)
    ap.add_argument("--out", type=Path, default=Path("benchmarks/results/marching_cubes.png"))
    args = ap.parse_args()
    fig, ax = plt.subplots(figsize=(8, 5.5))
    seed2 = {}
    for path in args.files:
        data = json.loads(path.read_text())
        cpus = data["machine"]["cpus"]
        lines = {}
        for row in data["results"]:
            seed2.update({row["cubes"]: row["seed2_gtx560_ms"]} if "seed2_gtx560_ms" in row else {})
            for (contender, method), label in LABELS.items():
                if method in row.get(contender, {}):
                    where = row[contender].get("device", f"{cpus} CPU cores")
                    lines.setdefault(f"{label} ({where})", []).append((row["cubes"], row[contender][method]))
        for label, points in lines.items():
            points.sort()
            ax.plot(*zip(*points), "o-", label=label)
    for k, name in enumerate(("per_cube", "histopyramid")):
        points = sorted((cubes, ms[name]) for cubes, ms in seed2.items())
        if points:
            ax.plot(*zip(*points), "k--" if k else "k:", label=f"seed 2, GTX 560: {name.replace('_', ' ')}")
    ax.plot([162 * 322 * 162], [0.25], "r*", markersize=12, label="seed 2's target: 0.25 ms at 163x323x163 (H200)")
    ax.plot([162 * 322 * 162], [0.08], "m*", markersize=12, label="issue 15's: 0.08 ms at 163x323x163 (H200)")
    ax.set(xscale="log", yscale="log", xlabel="cubes", ylabel="ms per extraction",
           title="Marching cubes, five metaballs")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(args.out, dpi=120)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
