"""How long sampling a body's wall particles and clipping the fluid take, cold and from the geometry cache
(issue 33; sphcore/geometry.py): the shipped cylindrical tank (scenes/meshes/cylinder_tank.stl, radius 0.3 m,
height 0.6 m, 48 sides) as a container filled 0.4 m deep, at --spacing (8 mm: about 126,000 wall particles
with h = 4 dx), in a cache folder of its own. Printed: the particles, the cold time (an empty cache: the
distances computed), the time from the disk cache in a second process (the mesh loaded, the arrays read),
and a second Scene in the same process.

    .venv/bin/python benchmarks/geometry_sampling.py --spacing 0.008
"""
import argparse
import os
import subprocess
import sys
import tempfile
import time

from sphcore.paths import SCENE_DIR


def scene(dx):
    from sphcore.scene import Scene

    return Scene.from_dict({
        "physics": {"dimension": 3},
        "domain": {"box_min": [-0.348, -0.048, -0.348], "box_max": [0.348, 0.648, 0.348]},
        "fluid": {"spacing": dx, "blocks": [{"min": [-0.3, 0.0, -0.3], "max": [0.3, 0.4, 0.3]}]},
        "bodies": [{"name": "tank", "mesh": str(SCENE_DIR / "meshes" / "cylinder_tank.stl"), "fluid": "inside"}],
        "time": {"end": 1.0, "output_interval": 0.1}})


def timed(dx):
    """Seconds to make the scene (its bodies' geometry included), its wall and fluid particles."""
    start = time.perf_counter()
    s = scene(dx)
    seconds = time.perf_counter() - start
    return seconds, len(s.wall_positions()[0]), s.fluid_count()


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--spacing", type=float, default=0.008)
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(*timed(args.spacing))
        return
    with tempfile.TemporaryDirectory() as cache:
        env = {**os.environ, "SPHCORE_CACHE_DIR": cache}
        runs = [subprocess.run([sys.executable, __file__, "--spacing", str(args.spacing), "--child"], env=env,
                               capture_output=True, text=True, check=True).stdout.split() for _ in range(2)]
        os.environ["SPHCORE_CACHE_DIR"] = cache
        timed(args.spacing)
        again = timed(args.spacing)[0]
    (cold, walls, fluid), (warm, _, _) = [(float(a), int(b), int(c)) for a, b, c in runs]
    print(f"spacing {args.spacing:g} m: {walls} wall and {fluid} fluid particles; cold {cold:.1f} s, from the "
          f"cache {warm:.2f} s in a new process, {again:.3f} s in the same one")


if __name__ == "__main__":
    main()
