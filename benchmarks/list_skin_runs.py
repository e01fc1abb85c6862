"""Whole dam-break runs with and without reused neighbour lists (physics.list_skin), in one process on one backend.

The Martin & Moyce dam break of `sphcore validate dam-break` (--dimension 2, or 3 in a channel as deep as the column
is wide: --resolution particles across a and across the channel) in each --configs model of
sphcore.validate.configs, run from rest to --t-end once per --skins value (0: a sort and a scan every step), with
--per-submit steps a submit and no state read in between. Per run: steps, wall seconds per simulated second,
builds per step, the front at the end (the furthest particle with a third of the bulk's neighbours, as the validation
measures it) and the largest distance of a particle from the first run's (skin 0 by default: round-off grows in a
splash, so this is large where the front agrees), and with --profile each stage's ms per step (a second run, every
dispatch timed). Printed and written as JSON: the trade of the reused lists in a
whole run, where the flow's fastest particle sets how often they are built.

    python3 benchmarks/list_skin_runs.py --configs graphics engineering --out benchmarks/results/list_skin_runs_cpu.json
    python3 benchmarks/list_skin_runs.py --backend vulkan --dimension 3 --resolution 40 --configs graphics engineering
"""
import argparse
import json
import time
from pathlib import Path

import numpy as np

from sphcore.profile import Profile
from sphcore.scene import Scene
from sphcore.simulation import Simulation
from sphcore.sph.dfsph import CONTROL_BUILDS
from sphcore.validate.dam_break import dam_break_scene, furthest, min_neighbours


def run(scene, backend, t_end, per_submit, profile=None):
    """(row, final positions in particle order) of one run to t_end, the first submit untimed."""
    with Simulation(scene, backend, **({"profile": profile} if profile else {})) as sim:
        sim.advance(per_submit)  # (numba compiles, Vulkan records)
        first_time, first_step = sim.time, sim.step_count
        builds_before = int(sim.backend.read_buffer("control")[CONTROL_BUILDS])
        start = time.perf_counter()
        while sim.time < t_end:
            sim.advance(per_submit)
        wall = time.perf_counter() - start
        steps = sim.step_count - first_step
        builds = int(sim.backend.read_buffer("control")[CONTROL_BUILDS]) - builds_before
        row = {"particles": sim.n, "steps": steps, "simulated_s": sim.time - first_time, "wall_s": wall,
               "ms_per_step": 1e3 * wall / steps, "wall_per_simulated_s": wall / (sim.time - first_time),
               "builds_per_step": builds / steps if scene["physics.list_skin"] else 1.0,
               "device": getattr(getattr(sim.backend, "ctx", None), "device_name", "cpu (numba)")}
        return row, sim.read()["particle_x"]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--backend", default="numba")
    ap.add_argument("--dimension", type=int, default=2)
    ap.add_argument("--resolution", type=int, default=40)
    ap.add_argument("--configs", nargs="+", default=["graphics", "engineering"])
    ap.add_argument("--smoothing-ratio", type=float, help="h / dx where the configuration does not set it (graphics: 2)")
    ap.add_argument("--skins", type=float, nargs="+", default=[0.0, 0.1, 0.2])
    ap.add_argument("--t-end", type=float, default=0.5)
    ap.add_argument("--per-submit", type=int, default=50)
    ap.add_argument("--profile", action="store_true", help="also each run again with every dispatch timed")
    ap.add_argument("--out")
    args = ap.parse_args()
    rows = []
    for config in args.configs:
        settings = {"dimension": args.dimension, "resolution": args.resolution, "config": config,
                    "backend": args.backend}
        if args.dimension == 3:
            settings["depth"] = args.resolution
        if args.smoothing_ratio:
            settings["smoothing_ratio"] = args.smoothing_ratio
        base = json.loads(dam_break_scene(settings).to_json())
        plain = None
        for skin in args.skins:
            base["physics"]["list_skin"] = skin
            scene = Scene.from_dict(base)
            row, x = run(scene, args.backend, args.t_end, args.per_submit)
            plain = x if plain is None else plain
            x64 = x.astype(np.float64)
            row.update(config=config, list_skin=skin, dimension=args.dimension, resolution=args.resolution,
                       front_m=furthest(x64, x64[:, 0], scene.h, min_neighbours(scene)),
                       max_distance_from_first_run_m=float(np.abs(x - plain).max()))
            if args.profile:
                profile = Profile()
                run(scene, args.backend, args.t_end, args.per_submit, profile)
                row["profile"] = profile.rows()
            rows.append(row)
            print(f"{config}, list_skin {skin:g}: {row['particles']} particles, {row['steps']} steps, "
                  f"{row['ms_per_step']:.3f} ms a step, {row['wall_per_simulated_s']:.2f} s per simulated s, "
                  f"builds {row['builds_per_step']:.2f} a step, front {row['front_m']:.4f} m", flush=True)
    if args.out:
        Path(args.out).write_text(json.dumps({"settings": vars(args), "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
