#!/bin/bash
# Issue 31: what particle shifting (physics.shifting = "lind", config "engineering_shifting") buys against the
# recommended model without it (config "engineering"), on one NVIDIA GPU through Vulkan, one run after the other:
# the hydrostatic tank (sphcore validate tank), the Martin & Moyce front (dam-break) and the Buchner wall
# pressure (dam-break-pressure), each at the resolutions of $RES (default "40"; particles per column width a,
# per depth, per column height H), into $OUT (default benchmarks/results/shifting/): <case>_<res>_<config>.json
# and .log. Then, unless AB=0, the pair-term layer's speed against the shaders before it (benchmarks/forces_ab.py
# with $OLD_SHADERS, default out/h3_old_shaders: a copy of shaders/ with compute_forces.comp and integrate.comp
# of the commit before, `git show f215964:shaders/sph/compute_forces.comp`), 1 M particles in 3D, with and
# without reused lists, alternating. Each run stops after $LIMIT seconds (default 200).
# Run from the repository root on the device machine, with .gl, .whl (benchmarks/gpu_env.sh) and $OLD_SHADERS
# carried there.
set -u -o pipefail
OUT=${OUT:-benchmarks/results/shifting}
. benchmarks/gpu_env.sh
mkdir -p "$OUT"
for r in ${RES:-40}; do
    for case in ${CASES:-tank dam-break dam-break-pressure}; do
        for config in engineering engineering_shifting; do
            name=${case}_${r}_$config
            timeout "${LIMIT:-200}" python3 -m sphcore validate "$case" --backend vulkan --resolution "$r" \
                --config "$config" --out "/tmp/$name" > "$OUT/$name.log" 2>&1
            echo "$name rc=$? $(tr '\r' '\n' < "$OUT/$name.log" | grep -v '%|' | tail -1)"
            for f in /tmp/"$name"/*.json; do cp "$f" "$OUT/${name}_$(basename "$f")"; done 2>/dev/null
        done
    done
done
if [ "${AB:-1}" != 0 ]; then
    python3 benchmarks/forces_ab.py --old-shaders "${OLD_SHADERS:-out/h3_old_shaders}" --counts "${COUNTS:-1000000}" \
        --rounds 3 --out "$OUT/pair_layer_ab.json"
fi
exit 0
