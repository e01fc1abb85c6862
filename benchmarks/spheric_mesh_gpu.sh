#!/bin/bash
# SPHERIC test 2 on one GPU through Vulkan with its box obstacle given two ways, side by side (issue 33):
#   spheric_box   the box as domain.obstacles: mirror images across its faces (the default)
#   spheric_mesh  the box as a body from scenes/meshes/spheric_box.stl: Adami et al. 2012's wall particles, and the
#                 fluid's force on it
# both at dx = 0.02 m, dt at half the stability bound, 6 s. Run from the repository root on the device machine with
# the ignored folders .gl and .whl carried there (benchmarks/gpu_env.sh), .whl/geometry holding the trimesh, shapely
# and rtree wheels for its Python 3.12 (its scipy is the machine's), and OUT set to the folder the results go to.
set -u -o pipefail
. benchmarks/gpu_env.sh
python3 -m pip install -q --no-index --no-deps --no-compile --target /tmp/site .whl/geometry/*.whl || exit
export OMP_WAIT_POLICY=passive
run() {  # run NAME ARGS...: the case into $OUT/NAME, its log's last lines printed
    python3 -m sphcore validate spheric --out "$OUT/$1" --backend vulkan --t-end 6 "${@:2}" > "/tmp/$1.log" 2>&1
    echo "$1 rc=$?"
    tr '\r' '\n' < "/tmp/$1.log" | grep -v 'step/s' | tail -3
}
run spheric_box --obstacle box &
run spheric_mesh --obstacle mesh &
wait
