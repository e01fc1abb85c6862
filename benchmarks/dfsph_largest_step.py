"""DFSPH's largest step (issue 31): which time.dt the dfsph model should take. DFSPH chooses each step's dt
from time.cfl_number on the particle speed, capped by time.dt; the graphics model's fixed 1e-4 s capped it at a
step several times smaller than the state equation's. (numba, 16 cores: about 2 minutes)

tank_2d_dfsph (the dfsph model: Wendland C2 on 2 dx, omega 0.8; 400 particles) run to --t-end with time.dt
each of --dt (a number is the largest step; "auto" the dfsph model's: the viscous bound and the CFL step at the
free-fall speed), and beside it the state equation's step on the same tank: the engineering model's adaptive
dt. Written as JSON (--out, default benchmarks/results/dfsph_largest_step.json): per run the mean dt, steps,
stepping seconds, solver iterations, unconverged solves, and the speed and compression left at the end.

    .venv/bin/python benchmarks/dfsph_largest_step.py
"""
import argparse
import json
import os
import platform
import time
from pathlib import Path

import numba
import numpy as np

from sphcore.scene import Scene
from sphcore.simulation import Simulation

ROOT = Path(__file__).resolve().parents[1]


def run(config, t_end, backend):
    scene = Scene.from_dict(config)
    rho0 = scene["fluid.rest_density"]
    wall = 0.0
    with Simulation(scene, backend) as sim:
        while sim.time < t_end:
            start = time.perf_counter()
            sim.advance(20)
            wall += time.perf_counter() - start
        s = sim.read()
        log = sim.solver_log.array() if scene.dfsph else None
        steps, t = sim.step_count, sim.time
    speed = np.sqrt((s["particle_v"] ** 2).sum(1))
    compression = np.maximum(s["particle_rho"] / rho0 - 1.0, 0.0)
    row = {"model": scene["physics.model"], "time.dt": scene["time.dt"], "largest_step": scene._folded_dt(),
           "steps": steps, "t": t, "mean_dt": t / steps, "wall_s": wall, "wall_per_simulated_s": wall / t,
           "speed_median_end": float(np.median(speed)), "speed_max_end": float(speed.max()),
           "mean_compression_end": float(compression.mean())}
    if log is not None:
        row.update(dt_max=float(log[:, 1].max()), density_iterations_mean=float(log[:, 5].mean()),
                   divergence_iterations_mean=float(log[:, 3].mean()), unconverged_steps=int((log[:, 7] == 0).sum()))
    return row


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--t-end", type=float, default=2.0)
    ap.add_argument("--dt", nargs="+", default=["1e-4", "5e-4", "1e-3", "auto"])
    ap.add_argument("--backend", default="numba")
    ap.add_argument("--out")
    args = ap.parse_args()
    base = json.loads(Scene.load("tank_2d_dfsph").to_json())
    rows = []
    for dt in args.dt:
        config = json.loads(json.dumps(base))
        config["time"]["dt"] = dt if dt == "auto" else float(dt)
        rows.append(run(config, args.t_end, args.backend))
        print(json.dumps(rows[-1]))
    wcsph = json.loads(json.dumps(base))
    wcsph["physics"] = {"model": "engineering"}  # the state equation's step on the same tank
    wcsph["fluid"] = {k: v for k, v in base["fluid"].items() if k in ("blocks", "spacing", "viscosity", "stiffness")}
    wcsph["time"] = {"steps": base["time"]["steps"]}
    rows.append(run(wcsph, args.t_end, args.backend))
    print(json.dumps(rows[-1]))
    out = Path(args.out or ROOT / "benchmarks" / "results" / "dfsph_largest_step.json")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"case": "tank_2d_dfsph", "t_end": args.t_end, "backend": args.backend, "runs": rows,
                               "host": {"platform": platform.platform(), "cpu_count": os.cpu_count()},
                               "versions": {"python": platform.python_version(), "numba": numba.__version__}},
                              indent=1) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
