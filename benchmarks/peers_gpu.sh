#!/bin/bash
# The rows sent from GPU to GPU (sphcore.peers, SPHCORE_MPI_EXCHANGE=cuda) checked on the GPUs of one host: how the
# GPUs are linked (nvidia-smi topo -m), then scenes/dam_break_3d.toml at spacing $SPACING (default 0.005 m: 184,320
# particles), $STEPS steps (default 400; adaptive dt, Verlet; DT='"auto"' a fixed dt, where the exchange overlaps
# the step's end: parallel.Rank.overlap), run by the 1-rank driver and by `sphcore run` on 2
# ranks (cuda and host) and on 4 (cuda; where there are 4 GPUs), each final.npz compared bit for bit with the
# 1-rank one. One JSON line a case in $OUT/peers_gpu.json (default benchmarks/results/parallel_gpu), logs beside it.
# Run from the repository root with .gl and .whl carried (benchmarks/gpu_env.sh), as benchmarks/parallel_gpu.sh.
set -u -o pipefail
OUT=${OUT:-benchmarks/results/parallel_gpu}
. benchmarks/gpu_env.sh
PY=$(which python3)
mkdir -p "$OUT" /tmp/peers
OUT=$(realpath "$OUT")
nvidia-smi topo -m | tee "$OUT/topology.txt"
"$PY" -c "import cuda.bindings; print('cuda-bindings', cuda.bindings.__version__)"
sed -e "s/^spacing = .*/spacing = ${SPACING:-0.005}/" -e "s/^steps = .*/steps = ${STEPS:-400}/" \
    -e "s/^output_every = .*/output_every = 100000/" scenes/dam_break_3d.toml > /tmp/peers/dam.toml
[ -n "${DT:-}" ] && sed -i "/^\[time\]/a dt = $DT" /tmp/peers/dam.toml
GPUS=$(nvidia-smi --query-gpu=name --format=csv,noheader | wc -l)
run() {  # ranks, exchange, folder
    SPHCORE_MPI_EXCHANGE=$2 /usr/bin/mpiexec --allow-run-as-root --bind-to none -n "$1" \
        -x PYTHONPATH -x VK_DRIVER_FILES -x PYTHONUNBUFFERED -x SPHCORE_CACHE_DIR -x SPHCORE_MPI_EXCHANGE \
        bash -c 'CUDA_VISIBLE_DEVICES=$OMPI_COMM_WORLD_LOCAL_RANK exec "$0" "$@"' \
        "$PY" -m sphcore run /tmp/peers/dam.toml --backend vulkan --out "/tmp/peers/$3" --overwrite > "$OUT/peers_$3.log" 2>&1
    echo "$3: rc=$? $(tail -c 300 "$OUT/peers_$3.log")"
}
CUDA_VISIBLE_DEVICES=0 "$PY" -c "import sys, sphcore; from sphcore import parallel
parallel.run(sphcore.Scene.load('/tmp/peers/dam.toml'), out_dir='/tmp/peers/one', progress=False, backend='vulkan',
             overwrite=True)" > "$OUT/peers_one.log" 2>&1; echo "one: rc=$?"
run 2 cuda two_cuda
run 2 host two_host
[ "$GPUS" -ge 4 ] && run 4 cuda four_cuda
"$PY" - "$OUT/peers_gpu.json" <<'EOF'
import json, sys
from pathlib import Path
import numpy as np
one = np.load("/tmp/peers/one/final.npz")
for case in ("two_cuda", "two_host", "four_cuda"):
    path = Path("/tmp/peers", case, "final.npz")
    if not path.exists():
        continue
    other = np.load(path)
    line = {"case": case, "particles": len(one["position"]), "steps": int(one["step"]), "time": float(one["time"]),
            "bitwise": {name: bool(np.array_equal(one[name], other[name]))
                        for name in ("position", "velocity", "density", "pressure", "time", "dt", "step")}}
    print(json.dumps(line))
    with open(sys.argv[1], "a") as f:
        f.write(json.dumps(line) + "\n")
EOF
