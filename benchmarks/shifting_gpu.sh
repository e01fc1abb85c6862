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
# Run from the repository root on the device machine, with .gl, .whl and $OLD_SHADERS carried there; where the
# NVIDIA Vulkan driver is not found (vkCreateInstance: "Found no drivers"), also the glvnd libraries
# (apt-get download libegl1 libglvnd0 libopengl0 libgl1 libglx0 libgles2 into $EXTRA_DEBS, default out/h3_gl).
set -u -o pipefail
OUT=${OUT:-benchmarks/results/shifting}
for f in .gl/*.deb ${EXTRA_DEBS:-out/h3_gl}/*.deb; do [ -f "$f" ] && dpkg -x "$f" /; done
ldconfig
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl || exit
export PYTHONPATH=/tmp/site:. VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json \
       PYTHONUNBUFFERED=1 SPHCORE_CACHE_DIR=/tmp/spvcache
nvidia-smi --query-gpu=name,driver_version --format=csv,noheader
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
