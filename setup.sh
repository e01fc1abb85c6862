#!/usr/bin/env bash
# Set up a Debian/Ubuntu machine for sphcore: Vulkan on the CPU (lavapipe), the validation
# layers, the GLSL compilers, OpenGL through EGL on the CPU (llvmpipe, for `sphcore render`'s
# offscreen pictures: no X server needed), and the project with its test and docs extras in .venv, a
# virtual environment made from the distribution's python3 (PEP 668: Debian 12 and Ubuntu 24.04
# refuse `pip install` into the system interpreter). Safe to run again: it installs only what
# is missing.
set -euo pipefail
cd "$(dirname "$0")"
packages=(mesa-vulkan-drivers libvulkan1 vulkan-tools vulkan-validationlayers glslang-tools glslc spirv-tools
          libegl1 libegl-mesa0 libgl1-mesa-dri python3-venv)
missing=()
for p in "${packages[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
    sudo=""; [ "$(id -u)" -eq 0 ] || sudo="sudo"
    $sudo apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq "${missing[@]}"
fi
# a .venv whose interpreter is gone (python3 upgraded or moved) is made anew
.venv/bin/python -c "" 2>/dev/null || python3 -m venv --clear .venv
.venv/bin/python -m pip install -q --disable-pip-version-check -e ".[test,docs]"
# one run on several ranks (sphcore[mpi]: mpi4py and an MPI from PyPI, for tests/test_parallel.py); without it
# those tests skip, so a failed install leaves the rest working
.venv/bin/python -m pip install -q --disable-pip-version-check -e ".[mpi]" \
    || echo "setup.sh: sphcore[mpi] did not install: runs on several ranks and their tests are skipped" >&2
