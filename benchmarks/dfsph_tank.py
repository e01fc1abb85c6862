"""The hydrostatic tank at rest with DFSPH (issue 14): does the density error stay under
fluid.max_density_error, and what pressure does the solve settle to?

The tank of `sphcore validate tank` (sphcore.validate.tank: 1 m wide, 0.6 m deep) with
physics.pressure_solver = "dfsph", run for --t-end seconds on --backend. Printed and written as JSON
(--out): the solver log's errors and iterations per step, the particles' mean compression
max(rho / rho_0 - 1, 0) at every sample, the speed left (largest, 99th percentile, median), and the
pressure slope against rho_0 g. --relaxation, --kernel and --smoothing-ratio set fluid.relaxation,
physics.kernel and fluid.smoothing_ratio (the tank's own: 1, mueller, 2).

    .venv/bin/python benchmarks/dfsph_tank.py --resolution 30 --t-end 2 --out /tmp/dfsph_tank.json
    .venv/bin/python benchmarks/dfsph_tank.py --kernel wendland_c2 --relaxation 0.8 --out /tmp/relaxed.json
"""
import argparse
import json
import time

import numpy as np

from sphcore.scene import Scene
from sphcore.simulation import Simulation
from sphcore.validate.tank import DEPTH, G, tank_scene


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolution", type=int, default=30, help="particles per depth")
    ap.add_argument("--t-end", type=float, default=2.0)
    ap.add_argument("--backend", default="numba")
    ap.add_argument("--max-density-error", type=float, default=0.001)
    ap.add_argument("--dt-fraction", type=float, default=1.0, help="of the largest step (time.dt_fraction)")
    ap.add_argument("--relaxation", type=float, default=1.0, help="fluid.relaxation (omega)")
    ap.add_argument("--kernel", default="mueller", help="physics.kernel")
    ap.add_argument("--smoothing-ratio", type=float, default=2.0, help="fluid.smoothing_ratio (h / dx)")
    ap.add_argument("--out")
    args = ap.parse_args()
    base = tank_scene({"resolution": args.resolution, "smoothing_ratio": args.smoothing_ratio})
    config = json.loads(base.to_json())
    config["physics"]["pressure_solver"] = "dfsph"
    config["fluid"]["max_density_error"] = args.max_density_error
    config["time"]["dt"] = "auto"
    config["time"]["dt_fraction"] = args.dt_fraction
    config["fluid"]["relaxation"] = args.relaxation
    config["physics"]["kernel"] = args.kernel
    scene = Scene.from_dict(config)
    rho0 = scene["fluid.rest_density"]
    samples, wall = [], 0.0
    with Simulation(scene, args.backend) as sim:
        while sim.time < args.t_end:
            start = time.perf_counter()
            sim.advance(20)
            wall += time.perf_counter() - start
            s = sim.read()
            compression = np.maximum(s["particle_rho"] / rho0 - 1.0, 0.0)
            speed = np.sqrt((s["particle_v"] ** 2).sum(1))
            samples.append((sim.time, float(compression.mean()), float(compression.max()), float(speed.max()),
                            float(np.percentile(speed, 99)), float(np.median(speed))))
        x, p = s["particle_x"], s["particle_p"]
        surface = x[:, 1].max() + scene["fluid.spacing"] / 2
        depth = surface - x[:, 1]
        bulk = (depth > 2 * scene.h) & (depth < DEPTH - 2 * scene.h)
        slope = float(np.polyfit(depth[bulk], p[bulk], 1)[0] / (rho0 * G))
        log = sim.solver_log.array()
        steps, t = sim.step_count, sim.time
    second = [r for r in samples if r[0] >= args.t_end / 2]
    result = {
        "particles": sim.n, "steps": steps, "t": t, "wall_s": wall, "wall_per_simulated_s": wall / t,
        "mean_dt": t / steps, "max_density_error": args.max_density_error,
        "solver_density_error_max": float(log[:, 6].max()), "unconverged_steps": int((log[:, 7] == 0).sum()),
        "density_iterations_mean": float(log[:, 5].mean()), "divergence_iterations_mean": float(log[:, 3].mean()),
        "mean_compression_max": max(r[1] for r in samples),
        "mean_compression_second_half_max": max(r[1] for r in second),
        "largest_compression_second_half": max(r[2] for r in second),
        "speed_max_second_half": max(r[3] for r in second),
        "speed_p99_second_half": max(r[4] for r in second),
        "speed_median_second_half": max(r[5] for r in second),
        "pressure_slope_over_rho0_g": slope, "relaxation": args.relaxation, "kernel": args.kernel,
        "smoothing_ratio": args.smoothing_ratio,
    }
    print(json.dumps(result, indent=1))
    if args.out:
        with open(args.out, "w") as f:
            json.dump({**result, "samples": samples}, f, indent=1)


if __name__ == "__main__":
    main()
