"""DFSPH against WCSPH by the cost of their steps alone (issue 14), in one process on one device.

The 3D Martin & Moyce dam break of `sphcore validate dam-break --dimension 3` (a channel as deep as the
column is wide: --resolution particles across a and across the channel), the same model with either
pressure solver (config "graphics" or "dfsph", with --kernel), stepped for --steps steps after --warm
steps, --per-submit steps per submit, the state left on the device: ms per step, and with each
solver's mean dt from a full run (--dt-from: the JSONs of benchmarks/dfsph_gpu.sh, keyed by
mm3d_<resolution>_<solver>.json) the wall time per simulated second. Printed and written as JSON.
With --profile, each solver then runs --steps more steps with a GPU timestamp after every dispatch
(sphcore.profile): its per-stage table is printed and saved in its row (the timed steps stay unprofiled).

    python3 benchmarks/dfsph_steps.py --backend vulkan --resolution 40 80 --dt-from benchmarks/results/dfsph/h200 \\
        --out benchmarks/results/dfsph/h200/steps.json
"""
import argparse
import json
import time
from pathlib import Path

from sphcore.profile import Profile
from sphcore.scene import Scene
from sphcore.simulation import Simulation
from sphcore.validate.dam_break import dam_break_scene

SOLVERS = {"state_equation": "graphics", "dfsph": "dfsph"}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--backend", default="vulkan")
    ap.add_argument("--resolution", type=int, nargs="+", default=[40])
    ap.add_argument("--kernel", default="wendland_c2")
    ap.add_argument("--steps", type=int, default=50)
    ap.add_argument("--warm", type=int, default=10)
    ap.add_argument("--per-submit", type=int, default=10)
    ap.add_argument("--dt-from", help="folder of benchmarks/dfsph_gpu.sh's JSONs (each solver's mean dt)")
    ap.add_argument("--profile", action="store_true", help="also a per-stage profile of each solver")
    ap.add_argument("--max-iterations", type=int, help="DFSPH's fluid.max_iterations (default: the scene's, 100): "
                    "each recorded iteration that finds its solve stopped is still three empty dispatches")
    ap.add_argument("--out")
    args = ap.parse_args()
    rows = []
    for r in args.resolution:
        for solver, config in SOLVERS.items():
            scene = dam_break_scene({"dimension": 3, "resolution": r, "depth": r, "config": config,
                                     "kernel": args.kernel, "backend": args.backend})
            if args.max_iterations and solver == "dfsph":
                data = json.loads(scene.to_json())
                data["fluid"]["max_iterations"] = args.max_iterations
                scene = Scene.from_dict(data)
            profile = Profile() if args.profile else None
            with Simulation(scene, args.backend, **({"profile": profile} if profile else {})) as sim:
                sim.backend.profile = None  # the timed steps: no timestamps
                sim.advance(args.warm)
                sim.read()
                resumed, start = getattr(sim.backend, "resumptions", 0), time.perf_counter()
                for _ in range(args.steps // args.per_submit):
                    sim.advance(args.per_submit)
                sim.backend.read_buffer("time_state")  # (waits for the device)
                seconds = (time.perf_counter() - start) / (args.steps // args.per_submit * args.per_submit)
                timed = args.steps // args.per_submit * args.per_submit
                log = sim.solver_log.array()[-timed:] if solver == "dfsph" else None
                row = {"resolution": r, "particles": sim.n, "solver": solver, "ms_per_step": 1e3 * seconds,
                       "max_iterations": scene["fluid.max_iterations"] if solver == "dfsph" else None,
                       "unconverged_steps": int((log[:, 7] == 0).sum()) if log is not None else None,
                       # the timed steps' mean iterations per solve, and (Vulkan) the windows' resumptions
                       "divergence_iterations": float(log[:, 3].mean()) if log is not None else None,
                       "density_iterations": float(log[:, 5].mean()) if log is not None else None,
                       "resumptions": getattr(sim.backend, "resumptions", 0) - resumed if log is not None else None,
                       "device": getattr(getattr(sim.backend, "ctx", None), "device_name", "cpu (numba)")}
                if profile:
                    sim.backend.profile = profile
                    sim.advance(args.steps)
                    sim.backend.read_buffer("time_state")
                    row["profile"] = profile.rows()
                    print(profile.table(), flush=True)
            if args.dt_from:
                full = json.loads((Path(args.dt_from) / f"mm3d_{r}_{solver}.json").read_text())
                row.update(mean_dt=full["mean_dt"], wall_per_simulated_s=seconds / full["mean_dt"],
                           rms_Z_table2=full["rms_Z_table2"])
            rows.append(row)
            print(json.dumps(row), flush=True)
    for r in args.resolution:
        mine = {row["solver"]: row for row in rows if row["resolution"] == r}
        if args.dt_from:
            print(f"{r} across a: DFSPH / WCSPH wall time per simulated second = "
                  f"{mine['dfsph']['wall_per_simulated_s'] / mine['state_equation']['wall_per_simulated_s']:.2f}")
    if args.out:
        Path(args.out).write_text(json.dumps({"settings": vars(args), "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
