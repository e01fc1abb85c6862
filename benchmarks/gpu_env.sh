# Sourced by the benchmarks/*.sh scripts on the GPU machine (`. benchmarks/gpu_env.sh`), from the repository
# root with the ignored folders .gl (the Vulkan loader, the GL vendor-neutral libraries the NVIDIA driver loads,
# glslang and spirv-tools as Debian packages) and .whl (the vulkan, cffi, pycparser and tqdm wheels for its
# Python 3.12) carried there: unpacks and installs them, points Vulkan at the NVIDIA driver and prints the GPU.
# SPHCORE_CACHE_DIR defaults to /tmp/spvcache (a script may set its own before sourcing this).
for f in .gl/*.deb; do dpkg -x "$f" /; done
ldconfig
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl || exit
export PYTHONPATH=/tmp/site:. VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json \
       PYTHONUNBUFFERED=1 SPHCORE_CACHE_DIR=${SPHCORE_CACHE_DIR:-/tmp/spvcache}
nvidia-smi --query-gpu=name,driver_version --format=csv,noheader
