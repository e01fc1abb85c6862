"""The step with two versions of the shaders, alternating in one process: A (--old-shaders, a copy of shaders/
with compute_forces.comp and integrate.comp as they were before the pair-term layer, issue 31) and B (this
checkout's), each timed as steps_per_second.py times a case (its 3D dam break, grid, Tait, h = 2 dx), --rounds
times A then B, so a drift of the machine shows in both.

    python benchmarks/forces_ab.py --old-shaders out/old_shaders --counts 1000000 --rounds 3 \
        --out benchmarks/results/pair_layer_h100.json

Vulkan only (the numba mirrors are compared with /tmp copies of the two trees: docs/contributing.md).
"""
import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import steps_per_second as sps  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--old-shaders", type=Path, required=True)
    ap.add_argument("--counts", type=lambda t: [int(v) for v in t.split(",")], default=[1_000_000])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--list-skin", type=lambda t: [float(v) for v in t.split(",")], default=[0.0, 0.1],
                    help="physics.list_skin values (comma list)")
    ap.add_argument("--variant", action="append", default=[], metavar="NAME=DIR",
                    help="a further shaders folder to time beside A and B")
    ap.add_argument("--min-seconds", type=float, default=3.0)
    ap.add_argument("--steps-per-submit", type=int, default=64)
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args()
    stubbed = sps.stub_numba_if_missing()
    import sphcore.backends as backends
    shaders = {"A_before": args.old_shaders.resolve(), "B_after": backends.SHADER_DIR}
    shaders.update({v.split("=")[0]: Path(v.split("=")[1]).resolve() for v in args.variant})
    record = {"benchmark": "forces_ab", "versions": sps.versions(), "numba_stubbed": stubbed, "results": []}
    for n, skin in [(n, skin) for n in args.counts for skin in args.list_skin]:
        for r in range(args.rounds):
            for variant, folder in shaders.items():
                backends.SHADER_DIR = folder  # (the stage shaders are compiled from here; params.glsl is the same)
                device, row = sps.time_case("vulkan", n, 3, "grid", 128, args.steps_per_submit, 256,
                                            args.min_seconds, profile=True, list_skin=skin)
                row.update(variant=variant, round=r)
                record["device"] = device
                record["results"].append(row)
                print(f"{variant} n={n} skin={skin:g} round={r} {row['steps_per_second']:.2f} steps/s "
                      f"{row['ms_per_step']:.3f} ms/step  {device}", flush=True)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(record, indent=1) + "\n")


if __name__ == "__main__":
    main()
