#!/bin/bash
# The GPU step before and after a change (issue 31: "no H200 step regression"): benchmarks/steps_per_second.py
# from two source trees, A ($A, default base/: `git archive <commit> | tar -x -C base`, ignored) and B (this tree),
# alternating A B A B ... $ROUNDS times (default 3) in one session on one device, for each case below; then a
# summary of B / A per case (the median of the rounds' steps/s), printed and written to $OUT/summary.json.
# Cases: the 3D dam break of steps_per_second.py (Tait, h = 2 dx, a sort every step) at $COUNTS particles
# (default 1048576), and the same with the neighbour lists reused (physics.list_skin = 0.1).
# Run from the repository root on the device machine, with the ignored folders .gl and .whl (benchmarks/gpu_env.sh)
# and base/ carried there.
set -u -o pipefail
A=${A:-base}
OUT=${OUT:-benchmarks/results/step_ab}
. benchmarks/gpu_env.sh
mkdir -p "$OUT"
OUT=$(realpath "$OUT")
for round in $(seq 1 "${ROUNDS:-3}"); do
    for tree in "$A" .; do
        tag=$([ "$tree" = . ] && echo B || echo A)
        for skin in 0 0.1; do
            (cd "$tree" && PYTHONPATH=/tmp/site:. SPHCORE_CACHE_DIR=/tmp/cache_$tag python3 benchmarks/steps_per_second.py \
                --backend vulkan --counts "${COUNTS:-1048576}" --list-skin "$skin" --min-seconds 3 \
                --out "$OUT/${tag}_skin${skin}_$round.json" > "$OUT/${tag}_skin${skin}_$round.log" 2>&1)
            echo "round $round $tag skin $skin rc=$? $(tail -1 "$OUT/${tag}_skin${skin}_$round.log")"
        done
    done
done
python3 - "$OUT" <<'PY'
import json, statistics, sys
from pathlib import Path
out = Path(sys.argv[1])
summary = {}
for skin in ("0", "0.1"):
    rate = {tag: [r["steps_per_second"] for f in sorted(out.glob(f"{tag}_skin{skin}_*.json"))
                  for r in json.loads(f.read_text())["results"]] for tag in "AB"}
    if rate["A"] and rate["B"]:
        a, b = statistics.median(rate["A"]), statistics.median(rate["B"])
        summary[f"list_skin {skin}"] = {"A": rate["A"], "B": rate["B"], "ratio_B_over_A": b / a}
        print(f"list_skin {skin}: A {a:.1f} steps/s, B {b:.1f} steps/s, B / A = {b / a:.3f}  (A {rate['A']}, B {rate['B']})")
(out / "summary.json").write_text(json.dumps(summary, indent=1) + "\n")
PY
