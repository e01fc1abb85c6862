#!/bin/bash
# A whole `sphcore run` of $SHAPE particles (default 625 640 500: 200 M) on $RANKS GPUs (default 4) and its resume
# on as many ranks, with its checkpoints and final.npz (benchmarks/parallel_run.py), under the system Open MPI.
# $PHASE: run, resume or both (default). Results: $OUT (default
# benchmarks/results/parallel_gpu/parallel_run.json), a JSON line a call. Run from the repository root on a
# machine with several GPUs (kind nvidia-h200-x4), with .gl and .whl carried (benchmarks/gpu_env.sh).
set -u -o pipefail
. benchmarks/gpu_env.sh
python3 -c "import mpi4py, numba" || { echo "needs mpi4py (a cp312 wheel in .whl) and numba"; exit 1; }
df -h /tmp | tail -1
python3 benchmarks/parallel_run.py --shape ${SHAPE:-625 640 500} --ranks "${RANKS:-4}" --steps "${STEPS:-10}" \
    --more "${MORE:-10}" --phase "${PHASE:-both}" --run-dir "${RUN_DIR:-/tmp/parallel_run}" \
    --out "${OUT:-benchmarks/results/parallel_gpu/parallel_run.json}"
