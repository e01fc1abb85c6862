"""Plot steps/s against particle count from one or more steps_per_second.py JSON files.

    python benchmarks/plot_steps_per_second.py benchmarks/results/steps_per_second_*.json \
        --out benchmarks/results/steps_per_second.png

Log-log axes; seed 1's GTX 1070 frames/s (stored in every JSON) as a dashed reference, and a
dotted N^-2 guide through the first series' smallest count (all-pairs cost).
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

    fig, ax = plt.subplots(figsize=(7, 5))
    seed1, guide = None, None
    for path in args.files:
        data = json.loads(path.read_text())
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


if __name__ == "__main__":
    main()
