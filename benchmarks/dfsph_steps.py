"""DFSPH against WCSPH by the cost of their steps alone (issue 14), in one process on one device.

The 3D Martin & Moyce dam break of `sphcore validate dam-break --dimension 3` (a channel as deep as the
column is wide: --resolution particles across a and across the channel), the same model with either
pressure solver (config "graphics" or "dfsph", with --kernel), stepped for --steps steps after --warm
steps, --per-submit steps per submit, the state left on the device: ms per step, and with each
solver's mean dt from a full run (--dt-from: the JSONs of benchmarks/dfsph_gpu.sh, keyed by
mm3d_<resolution>_<solver>.json) the wall time per simulated second. Printed and written as JSON.
With --profile, each solver then runs --steps more steps with a GPU timestamp after every dispatch
(sphcore.profile): its per-stage table is printed and saved in its row (the timed steps stay unprofiled).
The timed steps are early ones (after --warm), before the impact; --whole-run also times each full run's
steps again from the start (the impact's iterations included). --cfl-number runs DFSPH at several CFL
numbers (the file of CFL c under --dt-from: mm3d_<resolution>_dfsph_cfl<c>.json, dfsph_gpu.sh's CFLS).
--list-skin s also runs WCSPH with its neighbour lists reused between builds (physics.list_skin = s: the same
pairs and dt, fewer sorts and scans).

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
    ap.add_argument("--cfl-number", type=float, nargs="+", help="DFSPH's time.cfl_number, one run each (default: "
                    "the scene's, 0.4); --dt-from's file for CFL c is mm3d_<resolution>_dfsph_cfl<c>.json")
    ap.add_argument("--whole-run", action="store_true", help="with --dt-from: also each full run's steps again from "
                    "the start, timed without reading the state back (the impact's iterations included)")
    ap.add_argument("--list-skin", type=float, default=0.0, help="also WCSPH with physics.list_skin = this")
    ap.add_argument("--out")
    args = ap.parse_args()
    rows = []
    runs = ([("state_equation", None, 0.0)] + ([("state_equation", None, args.list_skin)] if args.list_skin else [])
            + [("dfsph", cfl, 0.0) for cfl in args.cfl_number or [None]])
    for r in args.resolution:
        for solver, cfl, skin in runs:
            label = solver if cfl is None else f"dfsph_cfl{cfl:g}"  # (and the --dt-from file's name)
            scene = dam_break_scene({"dimension": 3, "resolution": r, "depth": r, "config": SOLVERS[solver],
                                     "kernel": args.kernel, "backend": args.backend, "cfl_number": cfl})
            if (args.max_iterations and solver == "dfsph") or skin:
                data = json.loads(scene.to_json())
                if skin:
                    data["physics"]["list_skin"] = skin
                else:
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
                row = {"resolution": r, "particles": sim.n, "solver": solver, "label": label, "list_skin": skin,
                       "cfl_number": scene["time.cfl_number"] if solver == "dfsph" else None,
                       "ms_per_step": 1e3 * seconds,
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
                full = json.loads((Path(args.dt_from) / f"mm3d_{r}_{label}.json").read_text())
                row.update(mean_dt=full["mean_dt"], wall_per_simulated_s=seconds / full["mean_dt"],
                           rms_Z_table2=full["rms_Z_table2"])
                if args.whole_run:
                    row["whole_run"] = whole_run(scene, args.backend, full["steps"], args.per_submit)
            rows.append(row)
            print(json.dumps(row), flush=True)
    for r in args.resolution:
        mine = [row for row in rows if row["resolution"] == r]
        wcsph = [row for row in mine if row["solver"] == "state_equation"]
        for row, base in ((row, base) for row in mine if row["solver"] == "dfsph" for base in wcsph) if args.dt_from else ():
            print(f"{r} across a, {row['label']}: DFSPH / WCSPH (list_skin {base['list_skin']:g}) wall time per "
                  f"simulated second = {row['wall_per_simulated_s'] / base['wall_per_simulated_s']:.2f}" + (
                      f"; over the whole run {row['whole_run']['wall_per_simulated_s']:.2f} / "
                      f"{base['whole_run']['wall_per_simulated_s']:.2f} s = "
                      f"{row['whole_run']['wall_per_simulated_s'] / base['whole_run']['wall_per_simulated_s']:.2f}"
                      if args.whole_run else ""))
    if args.out:
        Path(args.out).write_text(json.dumps({"settings": vars(args), "rows": rows}, indent=1))


def whole_run(scene, backend, steps, per_submit):
    """The `steps` steps of a full run (dfsph_gpu.sh's, to t = 0.5 s) again from the start, --per-submit steps a
    submit and the state left on the device: the wall time per simulated second, the first submit (whose
    command buffers Python records) untimed."""
    with Simulation(scene, backend) as sim:
        sim.advance(per_submit)
        first = sim.time
        start = time.perf_counter()
        while sim.step_count < steps:
            sim.advance(min(per_submit, steps - sim.step_count))
        sim.backend.read_buffer("time_state")  # (waits for the device)
        wall = time.perf_counter() - start
        simulated = sim.time - first
        out = {"steps": steps, "simulated_s": simulated, "wall_s": wall, "wall_per_simulated_s": wall / simulated}
        if scene.dfsph:
            log = sim.solver_log.array()
            out.update(divergence_iterations=float(log[:, 3].mean()), density_iterations=float(log[:, 5].mean()),
                       unconverged_steps=int((log[:, 7] == 0).sum()))
        return out


if __name__ == "__main__":
    main()
