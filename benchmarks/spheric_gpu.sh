#!/bin/bash
# SPHERIC test 2 on one NVIDIA H200 through Vulkan: what validation/results/spheric_test2.{csv,json,png}
# hold. Run from the repository root on the device machine, with the ignored folders .gl (the Vulkan
# loader and glslang debs), .whl (the vulkan, cffi and pycparser wheels for its Python 3.12) and
# .spvcache carried there, and OUT set to the folder the results go to:
#   bash benchmarks/spheric_gpu.sh            (OUT/dx0.02: the committed run, dx = 0.02 m, 6 s)
#   bash benchmarks/spheric_gpu.sh 0.01 300   (also dx = 0.01 m, given at most 300 s)
set -eu -o pipefail
for f in .gl/*.deb; do dpkg -x "$f" /; done
ldconfig
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl
export PYTHONPATH=/tmp/site:. VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json \
       PYTHONUNBUFFERED=1 SPHCORE_CACHE_DIR=.spvcache OMP_WAIT_POLICY=passive
nvidia-smi --query-gpu=name,driver_version --format=csv,noheader
python3 -m sphcore validate spheric --out "$OUT/dx0.02" --backend vulkan --spacing 0.02 --t-end 6 2>&1 \
    | tr '\r' '\n' | tee "$OUT/dx0.02.log"
if [ $# -ge 1 ]; then
    timeout "${2:-300}" python3 -m sphcore validate spheric --out "$OUT/dx$1" --backend vulkan --spacing "$1" \
        --t-end 6 2>&1 | tr '\r' '\n' | tee "$OUT/dx$1.log" || true
fi
