#!/bin/bash
# SPHERIC test 2 on one NVIDIA H200 through Vulkan: the two runs in validation/results/, side by side
# on the GPU (about 6 minutes in all, most of it reading the finer run's state back every 0.01 s):
#   spheric_test2.*        dx = 0.02 m, 85,400 particles, dt at half the stability bound (the default)
#   spheric_test2_dx0.01.* dx = 0.01 m, 676,500 particles, dt at the whole bound
# Run from the repository root on the device machine, with the ignored folders .gl (Vulkan loader
# and glslang debs), .whl (the vulkan, cffi and pycparser wheels for its Python 3.12) and .spvcache
# carried there, and OUT set to the folder the results go to. The PNGs were drawn here from the CSV
# and JSON with sphcore.validate.spheric.read_results and plot.
set -u -o pipefail
export SPHCORE_CACHE_DIR=.spvcache
. benchmarks/gpu_env.sh
export OMP_WAIT_POLICY=passive
run() {  # run NAME ARGS...: the case into $OUT/NAME, its log's last lines printed
    python3 -m sphcore validate spheric --out "$OUT/$1" --backend vulkan --t-end 6 "${@:2}" > "/tmp/$1.log" 2>&1
    echo "$1 rc=$?"
    tr '\r' '\n' < "/tmp/$1.log" | grep -v 'step/s' | tail -3
}
run spheric_test2 --spacing 0.02 --dt-fraction 0.5 &
run spheric_test2_dx0.01 --spacing 0.01 --dt-fraction 1 &
wait
