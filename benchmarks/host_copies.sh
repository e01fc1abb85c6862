#!/bin/bash
# benchmarks/host_copies.py on 1 and on every GPU of a host at once (rank r on GPU r, the system Open MPI as
# benchmarks/parallel_gpu.sh), then benchmarks/copy_overlap.py on GPU 0; with the folders .gl and .whl carried.
# Results: $OUT/host_copies.json (a line a run), $OUT/copy_overlap.json.
set -u -o pipefail
OUT=${OUT:-benchmarks/results/parallel_gpu}
. benchmarks/gpu_env.sh
PY=$(which python3)
mkdir -p "$OUT"
GPUS=$(nvidia-smi --query-gpu=name --format=csv,noheader | wc -l)
for n in 1 "$GPUS"; do
    timeout 200 /usr/bin/mpiexec --allow-run-as-root --bind-to none -n "$n" -x PYTHONPATH -x VK_DRIVER_FILES \
        -x PYTHONUNBUFFERED bash -c 'CUDA_VISIBLE_DEVICES=$OMPI_COMM_WORLD_LOCAL_RANK exec "$0" "$@"' \
        "$PY" benchmarks/host_copies.py "${MIB:-84}" "$OUT/host_copies.json" 2>&1 | grep -v "^ *$"
done
nvidia-smi topo -m
# a copy while the GPU steps, on GPU 0 ($OUT/copy_overlap.json)
CUDA_VISIBLE_DEVICES=0 timeout 200 "$PY" benchmarks/copy_overlap.py "${COUNT:-8400000}" | tee -a "$OUT/copy_overlap.json"
