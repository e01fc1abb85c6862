"""sphcore's DFSPH (numba backend) beside SPlisHSPlasH's own DFSPH on the same 3D dam break, in one run.

The case is `sphcore validate dam-break --dimension 3`'s: Martin & Moyce's column (a wide, 2a high)
against the end wall of a channel 8a long and `depth` particles wide, released at t = 0. Both sides
get the same spacing dx = a / resolution (SPlisHSPlasH: particle radius dx / 2; its cubic spline's
support 4 r = 2 dx is sphcore's h), the same DFSPH tolerances (0.1 % density, 0.1 % divergence,
SPlisHSPlasH's maxError and maxErrorV are in percent), the same CFL number (0.4 times the particle
diameter over the fastest particle: SPlisHSPlasH's cflMethod 1, cflFactor 1), the same largest step,
the same kinematic viscosity, and the same threads (OMP_NUM_THREADS; numba's threads likewise).
The walls differ by construction: SPlisHSPlasH samples them with boundary particles (Akinci et al.
2012, boundaryHandlingMethod 0: no volume map to build first), sphcore mirrors the fluid across them.

Cost per simulated second: sphcore: the stepping's wall time over the simulated time (its kernels
compiled before, as a warm run); SPlisHSPlasH: the "Time sum: SimStep" its `splash --no-gui` prints
over the simulated time (the sum of its time steps, "Total number: Time step size"), so its start-up
(loading, boundary sampling) is left out on both sides; its mean iterations and step are parsed too.
Never in CI: it needs `pip install pysplishsplash` (2.19, a cp311 wheel) in some environment; give its
`splash` with --splash. Writes a JSON with both sides and prints the ratio. `--sphcore-only vulkan` runs
sphcore's side alone through Vulkan (the GPU machine has no SPlisHSPlasH), after a short run in the same
process (a fresh process's first recordings, slow in Python, are left out, as numba's compiling is).

    python3 -m venv /tmp/splash && /tmp/splash/bin/pip install pysplishsplash
    OMP_NUM_THREADS=2 .venv/bin/python benchmarks/peer_splishsplash.py --splash /tmp/splash/bin/splash \\
        --resolution 20 --depth 12 --t-end 0.4 --out benchmarks/results/peer_splishsplash.json
"""
import argparse
import json
import os
import subprocess
import tempfile
import time
from pathlib import Path

GL_FIX = "/lib/x86_64-linux-gnu/libGLdispatch.so.0"  # the wheel's bundled GL dispatch segfaults without it


def sphcore_side(settings, t_end, backend="numba"):
    import numpy as np

    from sphcore.simulation import Simulation
    from sphcore.validate.dam_break import dam_break_scene

    scene = dam_break_scene(settings)
    with Simulation(scene, backend) as sim:  # its start compiles every stage (warm_up)
        wall = 0.0
        while sim.time < t_end:
            start = time.perf_counter()
            sim.advance(10)
            wall += time.perf_counter() - start
        state = sim.read()
        log = sim.solver_log.array()
        t, steps = sim.time, sim.step_count
    return scene, {
        "particles": sim.n, "steps": steps, "t": t, "wall_s": wall, "cost_per_simulated_s": wall / t,
        "mean_dt": t / steps, "density_iterations_mean": float(log[:, 5].mean()),
        "divergence_iterations_mean": float(log[:, 3].mean()), "unconverged_steps": int((log[:, 7] == 0).sum()),
        "front_x": float(np.asarray(state["particle_x"])[:, 0].max()), "device": sim.device_name,
    }


def splash_scene(scene, settings, largest_dt):
    """SPlisHSPlasH's JSON for the sphcore scene."""
    dx = scene["fluid.spacing"]
    lo, hi = scene["domain.box_min"], scene["domain.box_max"]
    block = scene["fluid.blocks"][0]
    size = [h - l for l, h in zip(lo, hi)]
    nu = scene.shear_viscosity / scene["fluid.rest_density"]
    return {
        "Configuration": {
            "particleRadius": dx / 2, "simulationMethod": 4, "gravitation": [0, -9.81, 0],
            "timeStepSize": largest_dt, "cflMethod": 1, "cflFactor": 1, "cflMaxTimeStepSize": largest_dt,
            "boundaryHandlingMethod": 0, "numberOfStepsPerRenderUpdate": 1000000, "enablePartioExport": False,
            "enableVTKExport": False, "particleAttributes": "velocity",
            "DFSPH": {"minIterations": 2, "maxIterations": scene["fluid.max_iterations"],
                      "maxError": 100 * scene["fluid.max_density_error"], "maxIterationsV": scene["fluid.max_iterations"],
                      "maxErrorV": 100 * scene["fluid.max_divergence_error"], "enableDivergenceSolver": True},
        },
        "Materials": [{"id": "Fluid", "density0": scene["fluid.rest_density"], "viscosityMethod": 1,
                       "Standard viscosity": {"viscosity": nu}}],
        "RigidBodies": [{"geometryFile": str(Path(os.environ.get("SPLASH_MODELS", "")) / "UnitBox.obj"),
                         "translation": [(l + h) / 2 for l, h in zip(lo, hi)], "rotationAxis": [1, 0, 0],
                         "rotationAngle": 0, "scale": size, "isDynamic": False, "isWall": True, "mapInvert": True,
                         "mapThickness": 0.0, "mapResolution": [20, 10, 10]}],
        "FluidBlocks": [{"denseMode": 0, "start": block["min"], "end": block["max"], "translation": [0, 0, 0],
                         "scale": [1, 1, 1]}],
    }


def parse_timing(stdout):
    """{name: value} of the "Time sum: X: v ms", "Average number: X: v" and "Total number: X: v" lines."""
    found = {}
    for line in stdout.splitlines():
        for prefix in ("Time sum: ", "Average number: ", "Total number: ", "Average time: "):
            if line.startswith(prefix) and ":" in line[len(prefix):]:
                name, value = line[len(prefix):].rsplit(":", 1)
                try:
                    found[prefix + name.strip()] = float(value.replace("ms", "").strip())
                except ValueError:
                    pass
    return found


def splash_wall(splash, scene_file, stop_at, out_dir, env):
    start = time.perf_counter()
    run = subprocess.run([splash, "--no-gui", "--no-initial-pause", "--stopAt", str(stop_at), "--output-dir",
                          str(out_dir), str(scene_file)], env=env, capture_output=True, text=True)
    wall = time.perf_counter() - start
    if run.returncode != 0:
        raise RuntimeError(f"splash failed ({run.returncode}): {run.stderr[-2000:]}{run.stdout[-2000:]}")
    return wall, run.stdout


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--splash", help="SPlisHSPlasH's `splash` (pip install pysplishsplash)")
    ap.add_argument("--sphcore-only", metavar="BACKEND", help="run sphcore's side alone, on BACKEND (numba or "
                    "vulkan: the GPU machine, which has no SPlisHSPlasH), and write it")
    ap.add_argument("--resolution", type=int, default=20, help="particles across the column width a")
    ap.add_argument("--depth", type=int, default=12, help="particles across the channel")
    ap.add_argument("--t-end", type=float, default=0.4, help="simulated seconds")
    ap.add_argument("--out", help="JSON file")
    args = ap.parse_args()

    settings = {"dimension": 3, "resolution": args.resolution, "depth": args.depth, "pressure_solver": "dfsph",
                "a": 0.25}
    if args.sphcore_only:  # (a short run first: the first recordings, as numba's compiling)
        sphcore_side(settings, min(0.05, args.t_end), args.sphcore_only)
        scene, ours = sphcore_side(settings, args.t_end, args.sphcore_only)
        print(json.dumps(ours, indent=1))
        if args.out:
            Path(args.out).write_text(json.dumps({"case": "Martin & Moyce column, 3D channel", "settings": settings,
                                                  f"sphcore_{args.sphcore_only}_dfsph": ours}, indent=1))
        return
    if not args.splash:
        ap.error("--splash is needed (or --sphcore-only BACKEND)")
    scene, ours = sphcore_side(settings, args.t_end)
    largest = float(scene.params(1)[0]["dt"])
    splash = Path(args.splash)
    models = next(p for p in (splash.parent / "data" / "models", splash.parent.parent / "data" / "models") if p.is_dir())
    os.environ["SPLASH_MODELS"] = str(models)
    env = {**os.environ, "LD_PRELOAD": GL_FIX}
    with tempfile.TemporaryDirectory() as tmp:
        scene_file = Path(tmp) / "dam_break_3d.json"
        scene_file.write_text(json.dumps(splash_scene(scene, settings, largest), indent=1))
        wall_end, stdout = splash_wall(splash, scene_file, args.t_end, Path(tmp) / "end", env)
    timing = parse_timing(stdout)
    t_sim = timing["Total number: Time step size"]
    theirs = {"wall_s_whole_run": wall_end, "t": t_sim, "step_s": timing["Time sum: SimStep"] / 1e3,
              "cost_per_simulated_s": timing["Time sum: SimStep"] / 1e3 / t_sim,
              "mean_dt": timing["Average number: Time step size"],
              "density_iterations_mean": timing["Average number: DFSPH - iterations"],
              "divergence_iterations_mean": timing["Average number: DFSPH - iterationsV"],
              "boundary_particles": next((int(line.rsplit(":", 1)[1]) for line in stdout.splitlines()
                                          if line.startswith("Number of boundary particles")), None),
              "timing": timing}
    result = {"case": "Martin & Moyce column, 3D channel", "settings": settings, "dx": scene["fluid.spacing"],
              "largest_dt": largest, "threads": os.environ.get("OMP_NUM_THREADS"), "sphcore_numba_dfsph": ours,
              "splishsplash_dfsph": theirs,
              "ratio_sphcore_over_splishsplash": ours["cost_per_simulated_s"] / theirs["cost_per_simulated_s"]}
    print(json.dumps({k: v for k, v in result.items() if k != "splishsplash_dfsph"} | {
        "splishsplash_cost_per_simulated_s": theirs["cost_per_simulated_s"]}, indent=1))
    print(f"sphcore numba DFSPH: {ours['cost_per_simulated_s']:.1f} s per simulated second ({ours['particles']} "
          f"particles, dt {ours['mean_dt'] * 1e3:.2f} ms, {ours['density_iterations_mean']:.1f} density iterations); "
          f"SPlisHSPlasH DFSPH: {theirs['cost_per_simulated_s']:.1f} s (dt {theirs['mean_dt'] * 1e3:.2f} ms, "
          f"{theirs['density_iterations_mean']:.1f} density iterations); ratio "
          f"{result['ratio_sphcore_over_splishsplash']:.2f}")
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
