#!/usr/bin/env bash
# Set up a Debian/Ubuntu machine for sphcore: Vulkan on the CPU (lavapipe), the validation
# layers, the GLSL compilers, OpenGL through EGL on the CPU (llvmpipe, for `sphcore render`'s
# offscreen pictures: no X server needed), and the project with its test extras. Safe to run again.
set -euo pipefail
cd "$(dirname "$0")"
packages=(mesa-vulkan-drivers libvulkan1 vulkan-tools vulkan-validationlayers glslang-tools glslc spirv-tools
          libegl1 libegl-mesa0 libgl1-mesa-dri)
missing=()
for p in "${packages[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
    sudo=""; [ "$(id -u)" -eq 0 ] || sudo="sudo"
    $sudo apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq "${missing[@]}"
fi
python3 -m pip install -q -e ".[test]"
