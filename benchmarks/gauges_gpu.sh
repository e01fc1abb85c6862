#!/bin/bash
# The gauges of a run on several GPUs against the 1-rank driver's, byte for byte: scenes/dam_break_obstacle_3d.toml
# (a pier, a body, with a force gauge on it, a pressure and a height gauge; the cuts along z cross the pier) for
# $STEPS steps (default 800: the front reaches the pier at 0.16 s, about step 380; DT='"auto"': a fixed dt, where the
# exchange overlaps the step's end), run on Vulkan by the 1-rank
# driver on the first GPU and by `sphcore run` on 2 ranks (GPU to GPU, and through host memory) and on 4 (GPU to
# GPU; where there are 4 GPUs), each run's gauges/*.csv and final.npz compared with the 1-rank ones.
# One JSON line a case in $OUT/gauges_gpu.json (default benchmarks/results/parallel_gpu), logs beside it.
# Run from the repository root with .gl and .whl carried (benchmarks/gpu_env.sh), as benchmarks/peers_gpu.sh.
set -u -o pipefail
OUT=${OUT:-benchmarks/results/parallel_gpu}
. benchmarks/gpu_env.sh
PY=$(which python3)
mkdir -p "$OUT" /tmp/gauges
OUT=$(realpath "$OUT")
sed -e "s/^end = .*/steps = ${STEPS:-800}/" -e "s|meshes/|$PWD/scenes/meshes/|" \
    scenes/dam_break_obstacle_3d.toml > /tmp/gauges/pier.toml
[ -n "${DT:-}" ] && sed -i "/^\[time\]/a dt = $DT" /tmp/gauges/pier.toml
run() {  # ranks, exchange, folder
    SPHCORE_MPI_EXCHANGE=$2 /usr/bin/mpiexec --allow-run-as-root --bind-to none -n "$1" \
        -x PYTHONPATH -x VK_DRIVER_FILES -x PYTHONUNBUFFERED -x SPHCORE_CACHE_DIR -x SPHCORE_MPI_EXCHANGE \
        bash -c 'CUDA_VISIBLE_DEVICES=$OMPI_COMM_WORLD_LOCAL_RANK exec "$0" "$@"' \
        "$PY" -m sphcore run /tmp/gauges/pier.toml --backend vulkan --out "/tmp/gauges/$3" --overwrite \
        > "$OUT/gauges_$3.log" 2>&1
    echo "$3: rc=$? $(tail -c 300 "$OUT/gauges_$3.log")"
}
CUDA_VISIBLE_DEVICES=0 "$PY" -c "import sphcore; from sphcore import parallel
parallel.run(sphcore.Scene.load('/tmp/gauges/pier.toml'), out_dir='/tmp/gauges/one', progress=False,
             backend='vulkan', overwrite=True)" > "$OUT/gauges_one.log" 2>&1; echo "one: rc=$?"
run 2 cuda two_cuda
run 2 host two_host
[ "$(nvidia-smi --query-gpu=name --format=csv,noheader | wc -l)" -ge 4 ] && run 4 cuda four_cuda
"$PY" - "$OUT/gauges_gpu.json" <<'EOF'
import json, sys
from pathlib import Path
import numpy as np
one = Path("/tmp/gauges/one")
for case in ("two_cuda", "two_host", "four_cuda"):
    other = Path("/tmp/gauges", case)
    if not (other / "final.npz").exists():
        continue
    a, b = np.load(one / "final.npz"), np.load(other / "final.npz")
    gauges = {}
    for csv in sorted((one / "gauges").glob("*.csv")):
        rows = np.loadtxt(csv, delimiter=",", skiprows=1, ndmin=2)
        gauges[csv.stem] = {"rows": len(rows), "bytes_equal": csv.read_bytes() == (other / "gauges" / csv.name).read_bytes(),
                            "largest": float(np.abs(rows[:, 1:]).max())}
    line = {"case": case, "particles": len(a["position"]), "steps": int(a["step"]), "time": float(a["time"]),
            "bitwise": {name: bool(np.array_equal(a[name], b[name]))
                        for name in ("position", "velocity", "density", "pressure", "time", "dt", "step")},
            "gauges": gauges}
    print(json.dumps(line))
    with open(sys.argv[1], "a") as f:
        f.write(json.dumps(line) + "\n")
EOF
