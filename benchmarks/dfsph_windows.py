"""How DFSPH's windows of recorded iterations are sized on Vulkan (issue 14; shaders/sph/dfsph.glsl: windows),
measured: the 3D Martin & Moyce dam break of benchmarks/dfsph_steps.py with DFSPH, --warm steps, then
--steps steps timed (--per-submit a call), for each sizing rule and look-back, and with the whole budget
recorded (no windows). Per row: ms per step, resumptions, the windows at the end, the solves' iterations.
Printed and written as JSON.

    python3 benchmarks/dfsph_windows.py --resolution 40 --out benchmarks/results/dfsph/h200/windows_40.json
"""
import argparse
import json
import time
from pathlib import Path

import sphcore.backends as backends
from sphcore.simulation import Simulation
from sphcore.validate.dam_break import dam_break_scene

RULES = {  # the window from the most iterations a solve took in the look-back
    "above most + 1": lambda most: 1 << (most + 1).bit_length(),  # (the default: VulkanBackend.next_window)
    "twice most": lambda most: 1 << (2 * most - 1).bit_length(),
}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolution", type=int, default=40)
    ap.add_argument("--lookbacks", type=int, nargs="+", default=[32, 64, 128])
    ap.add_argument("--steps", type=int, default=320)
    ap.add_argument("--warm", type=int, default=96)
    ap.add_argument("--per-submit", type=int, default=32)
    ap.add_argument("--out")
    args = ap.parse_args()
    scene = dam_break_scene({"dimension": 3, "resolution": args.resolution, "depth": args.resolution,
                             "config": "dfsph", "kernel": "wendland_c2", "backend": "vulkan"})
    cases = [(rule, lookback) for rule in RULES for lookback in args.lookbacks] + [(None, None)]
    rows, default = [], backends.VulkanBackend.next_window
    for rule, lookback in cases:
        if rule is not None:
            backends.WINDOW_LOOKBACK = lookback
            backends.VulkanBackend.next_window = staticmethod(
                lambda most, budget, size=RULES[rule]: min(budget, max(backends.LEAST_WINDOW, size(most))))
        with Simulation(scene, "vulkan") as sim:
            if rule is None:
                sim.backend.windows = None  # the whole budget recorded
            sim.advance(args.warm)
            resumed = sim.backend.resumptions
            start = time.perf_counter()
            for _ in range(args.steps // args.per_submit):
                sim.advance(args.per_submit)
            sim.backend.read_buffer("time_state")  # (waits for the device)
            steps = args.steps // args.per_submit * args.per_submit
            log = sim.solver_log.array()[-steps:]
            rows.append({"rule": rule or "whole budget", "lookback": lookback, "particles": sim.n,
                         "ms_per_step": 1e3 * (time.perf_counter() - start) / steps,
                         "resumptions": sim.backend.resumptions - resumed, "windows_at_end": sim.backend.windows,
                         "density_iterations_mean": float(log[:, 5].mean()),
                         "density_iterations_max": int(log[:, 5].max()),
                         "divergence_iterations_mean": float(log[:, 3].mean()),
                         "device": sim.backend.ctx.device_name})
        backends.VulkanBackend.next_window = default
        print(json.dumps(rows[-1]), flush=True)
    if args.out:
        Path(args.out).write_text(json.dumps({"settings": vars(args), "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
