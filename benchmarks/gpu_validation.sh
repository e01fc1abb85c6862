#!/usr/bin/env bash
# GPU figures for the validation report (run on a machine with a Vulkan GPU; CSV and JSON go
# to $OUT, default validation/results/gpu): the 2D dam break at the default resolution on
# Vulkan in float32 and float64 and at finer resolutions, the 3D dam break (seed 2's numerics:
# Tait, h = 2.857 dx) in a channel as wide as the column, and the stability matrix on Vulkan
# with the largest particle count the device allows.
set -uo pipefail
out=${OUT:-validation/results/gpu}
for p in float32 float64; do
    python3 -m sphcore validate dam-break --backend vulkan --precision "$p" --out "$out/dam_break_2d_$p"
done
for r in 80 160; do
    python3 -m sphcore validate dam-break --backend vulkan --resolution "$r" --out "$out/dam_break_2d_res$r"
done
python3 -m sphcore validate dam-break --backend vulkan --dimension 3 --resolution 24 --depth 24 \
    --equation-of-state tait --smoothing-ratio 2.857 --out "$out/dam_break_3d"
python3 -m sphcore validate stability --backend vulkan --largest --out "$out/stability"
rm -rf "$out"/stability/*/  # the cases' snapshots, not needed for the report
