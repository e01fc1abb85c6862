"""Peer benchmark on one GPU: sphcore's Vulkan step beside a Taichi CUDA port of the same step, in one
process, one after the other, at each particle count.

The case and constants are peer_taichi_cpu.py's (steps_per_second.py's 3D dam break: Tait, h = 2 dx,
about 33 neighbours, a counting sort every step); the Taichi side is peer_taichi_cpu.py's `run_taichi`
with `ti.init(arch=ti.cuda)` and the cell offsets from Taichi's parallel PrefixSumExecutor. sphcore
runs through steps_per_second.py's `time_case` (--steps-per-submit steps per command buffer, the
state on the device). Each side is timed for --min-seconds after its warm-up. Prints a table, writes
a JSON after every count (a killed run keeps what it measured) and, where matplotlib is importable,
a PNG beside it; `--plot FILE.json` draws the PNG from a JSON alone (the GPU machine has no
matplotlib). With --list-skin s > 0, sphcore also runs with its lists reused between builds
(physics.list_skin = s: the same pairs, fewer sorts), a second ratio.

The GPU machine has no Taichi: its cp312 wheel without taichi/_lib/c_api (unused by the Python API),
with dill, colorama and rich, zipped into .taichi/taichi_trim.zip (36 MB, under the 64 MiB that travel),
is unzipped there into a folder on PYTHONPATH. The zip is made here (it is not committed):

    pip download taichi==1.7.4 dill colorama rich --python-version 3.12 --only-binary=:all: --no-deps \
        --platform manylinux_2_27_x86_64 --platform any -d /tmp/tw
    mkdir /tmp/tw/site && cd /tmp/tw/site && for w in ../*.whl; do unzip -q $w; done
    rm -r taichi/_lib/c_api && zip -q -r -9 $REPO/.taichi/taichi_trim.zip .

and there:

    python3 -m zipfile -e .taichi/taichi_trim.zip /tmp/taichi && PYTHONPATH=/tmp/taichi:/tmp/site:. \\
        python3 benchmarks/peer_taichi_gpu.py --counts 65536,262144,1000000,8000000 --out $OUT/peer_taichi_gpu.json
"""
import argparse
import json
import platform
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from benchmarks.peer_taichi_cpu import run_taichi, sphcore_revision  # noqa: E402
from benchmarks.steps_per_second import ints, make_case, time_case, versions  # noqa: E402


def plot(record, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = record["rows"]
    n = [r["n"] for r in rows]
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(11, 4.2))
    ax.loglog(n, [r["sphcore_vulkan"]["particle_steps_per_second"] for r in rows], "o-", label="sphcore (Vulkan)")
    skin = record.get("list_skin", 0.0)
    if skin:
        ax.loglog(n, [r["sphcore_vulkan_skin"]["particle_steps_per_second"] for r in rows], "^-",
                  label=f"sphcore, lists reused (skin {skin:g} h)")
    ax.loglog(n, [r["taichi_cuda"]["particle_steps_per_second"] for r in rows], "s-", label="Taichi (CUDA)")
    ax.set(xlabel="particles", ylabel="particle-steps per second", title=f"3D dam-break step, {record['device']}")
    ax.legend()
    bx.semilogx(n, [r["ratio_sphcore_over_taichi"] for r in rows], "o-", color="k", label="sphcore / Taichi")
    if skin:
        bx.semilogx(n, [r["ratio_skin_over_taichi"] for r in rows], "^-", color="C2", label="lists reused / Taichi")
    bx.axhline(3.0, ls=":", color="gray", label="issue 15's target (3x)")
    bx.axhline(1.0, ls="--", color="gray")
    bx.set(xlabel="particles", ylabel="sphcore / Taichi", title="ratio, measured side by side", ylim=(0, None))
    bx.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    print(f"wrote {path}")


def peer_arguments(doc, out, skin=False):
    """The command line of a GPU peer benchmark (this one, peer_warp_gpu.py): counts, timing, output, --plot
    (`skin`: and --list-skin)."""
    ap = argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--counts", type=ints, default=[65536, 262144, 1000000, 8000000])
    ap.add_argument("--min-seconds", type=float, default=3.0)
    ap.add_argument("--steps-per-submit", type=int, default=64)
    ap.add_argument("--out", type=Path, default=Path(out))
    ap.add_argument("--plot", type=Path, help="only draw the PNG of this JSON")
    if skin:
        ap.add_argument("--list-skin", type=float, default=0.0,
                        help="also time sphcore with physics.list_skin = this (its lists reused between builds)")
    return ap.parse_args()


def peer_record(name, args, **peer_versions):
    """The JSON record of a GPU peer benchmark, before its rows."""
    return {"benchmark": name, "device": None, "versions": versions() | peer_versions | {
                "platform": platform.platform()},
            "sphcore_git": sphcore_revision(), "steps_per_submit": args.steps_per_submit,
            "min_seconds": args.min_seconds, "list_skin": getattr(args, "list_skin", 0.0), "rows": []}


def time_sphcore(n, args, list_skin=0.0):
    """(device, timings) of sphcore's case on Vulkan at n particles (steps_per_second.py's 3D grid case)."""
    return time_case("vulkan", n, 3, "grid", 128, args.steps_per_submit, args.steps_per_submit, args.min_seconds,
                     list_skin=list_skin)


def save(record, args, plot):
    """Writes the record to --out (after every row: a run cut short keeps its rows), and the PNG when done."""
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(record, indent=1, default=float) + "\n")
    if len(record["rows"]) < len(args.counts):
        return
    try:
        plot(record, args.out.with_suffix(".png"))
    except ImportError:
        print(f"no matplotlib here: draw the PNG with --plot {args.out}")


def main():
    args = peer_arguments(__doc__, "benchmarks/results/peer_taichi_gpu.json", skin=True)
    if args.plot:
        return plot(json.loads(args.plot.read_text()), args.plot.with_suffix(".png"))
    try:
        import taichi as ti
    except ImportError:
        sys.exit("taichi is not importable: pip install taichi (or unzip .taichi/taichi_trim.zip, see --help)")

    record = peer_record("peer_taichi_gpu", args, taichi=".".join(map(str, ti.__version__)))
    record["scene"] = make_case(args.counts[0], 3, "grid")[0].config
    print(f"{'N':>9} {'sphcore p-steps/s':>18} {'Taichi p-steps/s':>17} {'ratio':>6}", flush=True)
    for n in args.counts:
        device, mine = time_sphcore(n, args)
        scene, x0 = make_case(n, 3, "grid")
        theirs = run_taichi(ti, scene, x0, 0, args.min_seconds, arch=ti.cuda)
        ratio = mine["particle_steps_per_second"] / theirs["particle_steps_per_second"]
        record["device"] = device
        row = {"n": n, "sphcore_vulkan": mine, "taichi_cuda": theirs, "ratio_sphcore_over_taichi": ratio}
        if args.list_skin:
            row["sphcore_vulkan_skin"] = time_sphcore(n, args, args.list_skin)[1]
            row["ratio_skin_over_taichi"] = (row["sphcore_vulkan_skin"]["particle_steps_per_second"]
                                             / theirs["particle_steps_per_second"])
        record["rows"].append(row)
        skinned = f" {row['ratio_skin_over_taichi']:>6.2f} with lists reused" if args.list_skin else ""
        print(f"{n:>9} {mine['particle_steps_per_second']:>18.4g} {theirs['particle_steps_per_second']:>17.4g} "
              f"{ratio:>6.2f}{skinned}  ({device}; finite: {mine['finite']}, {theirs['finite']})", flush=True)
        save(record, args, plot)


if __name__ == "__main__":
    main()
