#!/bin/bash
# Issue 12's GPU figures: today's model ("graphics") against the recommended one ("engineering",
# sphcore/validate/configs.py) on one NVIDIA H200 (or H100) through Vulkan, into $OUT/model/
# (default validation/results/model/), the runs side by side on the GPU:
#   mm_engineering_80, _160     Martin & Moyce at 80 and 160 particles across a (graphics: results/gpu/dam_break_2d_res*)
#   mm_engineering_h2_*         the same with the support radius 2 dx (the scenes' default) instead of 4 dx
#   buchner_<config>_120        Buchner 2002 P1 pressure at H/120 (28,800 particles), graphics, engineering
#                               and engineering_h2
#   tank_<config>_60            the hydrostatic tank at 60 particles per depth, the same three
#   spheric_engineering         SPHERIC test 2, dx = 0.02 m, engineering, dt adaptive at the whole bound
# Run from the repository root on the device machine, with the ignored folders .gl (Vulkan loader
# and glslang debs) and .whl (the vulkan, cffi and pycparser wheels for its Python 3.12) carried
# there. TAR=1 packs the results into $OUT/model.tgz (the device tool brings back at most 8 files).
set -u -o pipefail
OUT=${OUT:-validation/results}
. benchmarks/gpu_env.sh
export OMP_WAIT_POLICY=passive
dir=$OUT/model
mkdir -p "$dir"
run() {  # run NAME ARGS...: `sphcore validate ARGS --out $dir/NAME --backend vulkan`, its log's last line printed
    timeout "${LIMIT:-540}" python3 -m sphcore validate "${@:2}" --backend vulkan --out "$dir/$1" > "$dir/$1.log" 2>&1
    echo "$1 rc=$? $(tr '\r' '\n' < "$dir/$1.log" | grep -v '%|' | tail -1)"
}
run spheric_engineering spheric --spacing 0.02 --t-end 6 --config engineering --adaptive-dt --dt-fraction 1 &
for c in graphics engineering engineering_h2; do
    run "buchner_${c}_120" dam-break-pressure --resolution 120 --config "$c" &
    run "tank_${c}_60" tank --resolution 60 --config "$c" &
done
for c in engineering engineering_h2; do
    for r in 80 160; do
        run "mm_${c}_$r" dam-break --resolution "$r" --config "$c" &
    done
done
wait
[ "${TAR:-0}" = 1 ] && tar -czf "$OUT/model.tgz" -C "$OUT" model && ls -la "$OUT/model.tgz"
exit 0
