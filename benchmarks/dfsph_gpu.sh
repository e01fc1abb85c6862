#!/bin/bash
# Issue 14's GPU figures: the 3D Martin & Moyce dam break (a channel RES particles deep) with WCSPH
# (config "graphics") and DFSPH (config "dfsph", the same model with physics.pressure_solver = "dfsph"),
# both with the options $MODEL (default "--kernel wendland_c2", the recommended model's kernel), on one
# NVIDIA GPU through Vulkan, one after the other (no run shares the GPU), for each of $SOLVERS (default
# "state_equation dfsph") at each resolution of $RES (default "40 80": 128,000 and 1,024,000
# particles), DFSPH at each CFL number of $CFLS (default: the scene's, 0.4; written as "%g" writes it: 1, not
# 1.0), into $OUT (default benchmarks/results/dfsph/h200/): mm3d_<RES>_<solver>[_cfl<CFL>].json
# (wall_per_simulated_s, mean_dt, the RMS of Z, DFSPH's iterations), .csv (the front and column
# height) and .log. Each run stops after $LIMIT seconds (default 240). Its wall times include reading
# the state back for every front sample; benchmarks/dfsph_steps.py times the steps alone.
# Run from the repository root on the device machine, with the ignored folders .gl (Vulkan loader and
# glslang debs) and .whl (the vulkan, cffi and pycparser wheels for its Python 3.12) carried there.
set -u -o pipefail
OUT=${OUT:-benchmarks/results/dfsph/h200}
. benchmarks/gpu_env.sh
mkdir -p "$OUT"
for r in ${RES:-40 80}; do
    for solver in ${SOLVERS:-state_equation dfsph}; do
      for cfl in $([ "$solver" = dfsph ] && echo "${CFLS:-default}" || echo default); do
        config=$([ "$solver" = dfsph ] && echo dfsph || echo graphics)
        name=mm3d_${r}_$solver$([ "$cfl" = default ] || echo "_cfl$cfl")
        timeout "${LIMIT:-240}" python3 -m sphcore validate dam-break --backend vulkan --dimension 3 \
            --resolution "$r" --depth "$r" --t-end 0.5 --config "$config" ${MODEL---kernel wendland_c2} \
            $([ "$cfl" = default ] || echo "--cfl-number $cfl") --out "/tmp/$name" > "$OUT/$name.log" 2>&1
        echo "$name rc=$? $(tr '\r' '\n' < "$OUT/$name.log" | grep -v '%|' | tail -1)"
        cp "/tmp/$name/dam_break_3d.json" "$OUT/$name.json" 2>/dev/null
        cp "/tmp/$name/dam_break_3d.csv" "$OUT/$name.csv" 2>/dev/null
      done
    done
done
exit 0
