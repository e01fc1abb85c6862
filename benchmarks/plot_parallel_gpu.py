"""Plot benchmarks/parallel_gpu.py's JSON lines: ms per step against GPUs, strong and weak scaling, with the part
the slowest rank's host spends in the exchange (rows between ranks: through host memory, or from GPU to GPU; the
Allgather's wait for the other ranks included) shaded, while its GPU runs the step's end beside it where they
overlap; prints the table with each case's efficiency (strong: T1 / (N TN); weak: T1 / TN; T1 the 1-rank driver's, and against the plain 1-GPU run where
measured) and writes it as JSON beside the plot.

    python benchmarks/plot_parallel_gpu.py benchmarks/results/parallel_gpu/parallel_gpu.json --out x.png
"""
import argparse
import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def table(rows):
    """One row per (scaling, ranks), the last line of each kept, with its efficiencies."""
    cases = {(r["scaling"], r["ranks"]): r for r in rows}
    out = []
    for (scaling, ranks), r in sorted(cases.items()):
        one = cases.get((scaling, 1))
        row = {"scaling": scaling, "ranks": ranks, "particles": r["particles"],
               "particles_per_rank": r["particles_per_rank"], "ms_per_step": r["ms_per_step"],
               "host_staged_share": r["host_staged_share"], "plain_ms_per_step": r.get("plain_ms_per_step")}
        if one is not None:
            ideal = one["ms_per_step"] / (ranks if scaling == "strong" else 1)
            row["efficiency"] = ideal / r["ms_per_step"]
            plain = one.get("plain_ms_per_step")
            if plain:
                row["efficiency_vs_plain"] = plain / (ranks if scaling == "strong" else 1) / r["ms_per_step"]
        out.append(row)
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("file", type=Path)
    ap.add_argument("--out", type=Path, default=Path("benchmarks/results/parallel_gpu/parallel_gpu.png"))
    args = ap.parse_args()
    rows = table([json.loads(line) for line in args.file.read_text().splitlines() if line.strip()])
    for r in rows:
        print(f"{r['scaling']:6} {r['ranks']} GPUs {r['particles']:>11,} particles: {r['ms_per_step']:9.2f} ms/step, "
              f"{100 * r['host_staged_share']:5.1f} % in the exchange, efficiency "
              f"{r.get('efficiency', float('nan')):.2f}"
              + (f" (against the plain 1-GPU run: {r['efficiency_vs_plain']:.2f})"
                 if "efficiency_vs_plain" in r else ""))
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.5))
    for ax, scaling in zip(axes, ("strong", "weak")):
        case = [r for r in rows if r["scaling"] == scaling]
        if not case:
            ax.set_visible(False)
            continue
        ranks = [r["ranks"] for r in case]
        ms = [r["ms_per_step"] for r in case]
        ax.bar(ranks, ms, width=0.6, color="tab:blue", label="step")
        ax.bar(ranks, [m * r["host_staged_share"] for m, r in zip(ms, case)], width=0.6, color="tab:orange",
               label="the host in the exchange (the GPU runs beside it)")
        ideal = [ms[0] / (n / ranks[0]) if scaling == "strong" else ms[0] for n in ranks]
        ax.plot(ranks, ideal, "k--", label="ideal")
        plain = case[0].get("plain_ms_per_step")
        if plain and scaling == "strong":
            ax.axhline(plain, color="tab:green", ls=":", label="plain run, 1 GPU")
        ax.set_xticks(ranks)
        ax.set_xlabel("GPUs (ranks)")
        ax.set_ylabel("ms per step")
        ax.set_title(f"{scaling} scaling, {case[0]['particles_per_rank' if scaling == 'weak' else 'particles']:,.0f} "
                     f"particles{' a GPU' if scaling == 'weak' else ''}")
        ax.legend(fontsize=8)
    fig.tight_layout()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, dpi=120)
    args.out.with_suffix(".summary.json").write_text(json.dumps(rows, indent=1) + "\n")
    print(f"-> {args.out}")


if __name__ == "__main__":
    main()
