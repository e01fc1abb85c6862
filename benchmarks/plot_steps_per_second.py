"""Plot steps/s against particle count from one or more steps_per_second.py JSON files.

    python benchmarks/plot_steps_per_second.py benchmarks/results/steps_per_second_*.json \
        --out benchmarks/results/steps_per_second.png

2D all-pairs files: steps/s, seed 1's GTX 1070 frames/s (stored in every JSON) dashed, and a
dotted N^-2 guide (all-pairs cost). 3D grid files (--dim 3): particle-steps per second, with
seed 2's GTX 560 and single-thread CPU figures (table 6.1) dashed and the 1e9 target dotted.
Log-log axes.
"""
import argparse
import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("files", nargs="+", type=Path)
    ap.add_argument("--out", type=Path, default=Path("benchmarks/results/steps_per_second.png"))
    args = ap.parse_args()

    datasets = [json.loads(path.read_text()) for path in args.files]
    if any(d.get("dim") == 3 for d in datasets):
        return plot_3d(datasets, args.out)
    fig, ax = plt.subplots(figsize=(7, 5))
    seed1, guide = None, None
    for data in datasets:
        rows = {}
        for r in data["results"]:  # one point per N: the best setting if the file is a sweep
            if r["n"] not in rows or r["steps_per_second"] > rows[r["n"]]["steps_per_second"]:
                rows[r["n"]] = r
        ns = sorted(rows)
        sps = [rows[n]["steps_per_second"] for n in ns]
        ax.plot(ns, sps, "o-", label=f"{data['backend']}: {data['device']}")
        guide = guide or (ns[0], sps[0], ns[-1])
        seed1 = seed1 or data.get("seed1_gtx1070_vulkan_fps")
    if seed1:
        ns = sorted(int(n) for n in seed1)
        ax.plot(ns, [seed1[str(n)] for n in ns], "s--", color="gray", label="seed 1, Vulkan, GTX 1070 (frames/s)")
    if guide:
        n0, s0, n1 = guide
        ns = [n0, max(n1, 2 * n0)]
        ax.plot(ns, [s0 * (n0 / n) ** 2 for n in ns], ":", color="black", lw=0.8, label="slope N^-2")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("particles N")
    ax.set_ylabel("steps per second")
    ax.set_title("sphcore all-pairs 2D SPH step")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(args.out, dpi=120)
    print(f"wrote {args.out}")


def plot_3d(datasets, out):
    fig, ax = plt.subplots(figsize=(7, 5))
    for data in datasets:
        rows = sorted(data["results"], key=lambda r: r["n"])
        skin = rows[0].get("list_skin", 0.0)  # (a run with the lists reused: physics.list_skin)
        ax.plot([r["n"] for r in rows], [r["particle_steps_per_second"] for r in rows], "^-" if skin else "o-",
                label=f"{data['backend']}: {data['device']}" + (f", lists reused (skin {skin:g} h)" if skin else ""))
    seed2 = next((d["seed2_ms_per_step_cpu_gpu"] for d in datasets if "seed2_ms_per_step_cpu_gpu" in d), None)
    if seed2:
        ns = sorted(int(n) for n in seed2)
        for k, name in ((1, "seed 2, GTX 560"), (0, "seed 2, Core 2 Q6600, one thread")):
            ax.plot(ns, [n / (seed2[str(n)][k] * 1e-3) for n in ns], "s--", color="gray" if k else "silver", label=name)
    ax.axhline(1e9, ls=":", color="black", lw=0.8, label="target at 1,000,000 (H200): 1e9")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("particles N")
    ax.set_ylabel("particle-steps per second")
    ax.set_title("sphcore 3D WCSPH step, grid neighbours")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(out, dpi=120)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
