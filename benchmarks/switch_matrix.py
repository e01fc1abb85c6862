"""The switch matrix (issue 30): combinations of the scene's switches (tests/test_switch_matrix.py: SWITCHES, the tiny
scenes, the comparison) run a few steps on numba and on Vulkan, compared: integers bit for bit, reals against the
test's FLOAT_RTOL. By default the whole product of the combinations the scene validation accepts (3,328 of 12,288;
each compiles its own numba mirrors: about 30 s of CPU a combination with a cold cache, a day for the product here,
and about a second with a warm one); --sample N runs the test's covering sample (every pair of switch values in 12
combinations), then further accepted ones in the sample's seeded order, up to N.

Per combination: pass or fail, what failed, the largest difference of each real buffer (of its scale), the seconds.
A table on stdout and JSON in --out, rewritten after each combination (an interrupted run keeps its rows).

    python3 benchmarks/switch_matrix.py --sample 12
    python3 benchmarks/switch_matrix.py --out benchmarks/results/switch_matrix_full.json
"""
import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
import test_switch_matrix as matrix  # noqa: E402  (the matrix's definition, shared with its CI test)


def chosen(valid, sample):
    """The combinations to run: all of `valid`, or the covering sample and then the rest in a seeded order, `sample`
    in all."""
    if not sample:
        return valid
    cover = matrix.covering_sample(valid, size=sample)
    rest = [valid[k] for k in np.random.default_rng(matrix.SEED).permutation(len(valid)) if valid[k] not in cover]
    return (cover + rest)[:sample]


def row_of(combo, steps, validation):
    """One combination's result (a run that raises is a failure naming the exception)."""
    start = time.perf_counter()
    try:
        out, scene = matrix.run_both(combo, steps, validation)
        found = matrix.differences(out, scene)
        failed = matrix.failures(found)
        n = len(out["numba"][0]["particle_id"])
    except Exception as e:  # (recorded, and the matrix goes on)
        found, failed, n = {}, [f"{type(e).__name__}: {e}".splitlines()[0]], 0
    return {"label": matrix.label(combo), "combo": combo, "particles": n, "pass": not failed, "failures": failed,
            "max_rel_diff": {k: v for k, (kind, v) in found.items() if kind == "float"},
            "integers_equal": {k: v for k, (kind, v) in found.items() if kind == "int"},
            "seconds": round(time.perf_counter() - start, 2)}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sample", type=int, default=0, help="combinations to run (0: the whole product)")
    parser.add_argument("--steps", type=int, default=matrix.STEPS, help="steps per run")
    parser.add_argument("--no-validation", action="store_true", help="Vulkan without its validation layers")
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "switch_matrix.json")
    args = parser.parse_args(argv)
    if args.sample < 0 or args.steps < 1:
        parser.error("--sample must be 0 or more and --steps 1 or more")
    result = {"switches": matrix.SWITCHES, "steps": args.steps, "float_rtol": matrix.FLOAT_RTOL, "rows": []}
    try:  # (before anything runs: an --out that cannot be written is refused at once)
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(result, indent=1) + "\n")
    except OSError as e:
        parser.error(f"--out {args.out}: cannot write ({e.strerror})")
    valid, refused = matrix.accepted(matrix.ALL)
    combos = chosen(valid, args.sample)
    result.update(combinations=len(matrix.ALL), refused=len(refused), accepted=len(valid))
    print(f"{len(matrix.ALL)} combinations, {len(refused)} refused by the scene validation, {len(valid)} accepted; "
          f"running {len(combos)}, {args.steps} steps each, reals within {matrix.FLOAT_RTOL:g} of their scale")
    floats = matrix.FLOATS
    print(f"{'pass':5} {'s':>6} " + " ".join(f"{name.removeprefix('particle_'):>8}" for name in floats)
          + "  combination")
    for combo in tqdm(combos, unit="combination", file=sys.stderr):
        row = row_of(combo, args.steps, not args.no_validation)
        result["rows"].append(row)
        diffs = " ".join(f"{row['max_rel_diff'].get(name, float('nan')):8.1e}" for name in floats)
        tqdm.write(f"{'ok' if row['pass'] else 'FAIL':5} {row['seconds']:6.1f} {diffs}  {row['label']}"
                   + ("" if row["pass"] else f"\n      {'; '.join(row['failures'])}"))
        args.out.write_text(json.dumps(result, indent=1) + "\n")
    rows = result["rows"]
    worst = {name: max((r["max_rel_diff"].get(name, 0.0) for r in rows), default=0.0) for name in floats}
    print(f"{sum(r['pass'] for r in rows)} of {len(rows)} passed in {sum(r['seconds'] for r in rows):.0f} s; largest "
          "differences of their scale: " + ", ".join(f"{k} {v:.2g}" for k, v in worst.items()) + f"; JSON: {args.out}")
    return 0 if all(r["pass"] for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
