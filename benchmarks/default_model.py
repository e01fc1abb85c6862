"""The default model on Buchner 2002's dam break (issue 31): a scene that gives only its geometry, its sound
speed and its end time runs to t sqrt(g / H) = 7 without a blow-up. (numba, 2 cores: about 2 minutes)

The case of `sphcore validate dam-break-pressure` (sphcore.validate.buchner: a column H = 0.6 m high and 2H
wide against the left wall of a tank 3.22 m long and 4 m high) at dx = H / --resolution (30), written as a
user would write it from `sphcore keys`: domain.box_max, fluid.blocks, fluid.spacing, fluid.stiffness
(c = 20 sqrt(g H), as the validation case) and time.end; every other key is the default, so the model is
physics.model's default (--model names another, e.g. graphics, for comparison). Stepped to time.end,
sampling the wall pressure at P1 every 0.01 in t* (sphcore.validate.buchner's sensor and metrics).

Written as JSON (--out, default benchmarks/results/default_model_<model>_H<resolution>.json): whether the
run reached the end, the t* where it stopped, steps, mean dt, stepping seconds, and the P1 metrics against
the measured series (impact peak, RMS of p* to t* = 7).

    .venv/bin/python benchmarks/default_model.py
    .venv/bin/python benchmarks/default_model.py --model graphics   # the old default: blows up
"""
import argparse
import json
import math
import os
import platform
import subprocess
from pathlib import Path

import numba
import numpy as np

from sphcore.scene import Scene
from sphcore.validate import buchner
from sphcore.validate.sensors import wall_pressure

ROOT = Path(__file__).resolve().parents[1]
T_END_STAR = 7.0  # t sqrt(g / H)


def default_scene(resolution=30, model=None, H=0.6):
    """The Buchner 2002 dam break at dx = H / resolution with only geometry, sound speed and end time (and
    physics.model where `model` is given)."""
    g = buchner.G
    data = {
        "name": "default_model_buchner",
        "domain": {"box_max": [buchner.TANK_LENGTH * H, buchner.TANK_HEIGHT]},
        "fluid": {"blocks": [{"min": [0.0, 0.0], "max": [2 * H, H]}], "spacing": H / resolution,
                  "stiffness": (20.0 * math.sqrt(g * H)) ** 2},
        "time": {"end": T_END_STAR / math.sqrt(g / H)},
    }
    if model:
        data["physics"] = {"model": model}
    return Scene.from_dict(data, source="benchmarks/default_model.py")


def run(scene, backend="numba", progress=True, H=0.6):
    """(rows, info) of scene stepped to its time.end (buchner.sample_run), sampling p* at P1."""
    scale = math.sqrt(buchner.G / H)
    sensor = (buchner.TANK_LENGTH * H, buchner.SENSOR_Y)
    lo, hi = scene["domain.box_min"], scene["domain.box_max"]

    def sample(state, t):
        p = wall_pressure(state["particle_x"], state["particle_p"], sensor, scene.h, lo, hi)
        return {"t": t, "t_star": t * scale, "p_star": p / (buchner.RHO0 * buchner.G * H)}

    return buchner.sample_run(scene, backend, scene.end_time, buchner.SAMPLE_DT_STAR / scale, sample, progress,
                              f"default model [{scene['physics.model']}]")


def commit():
    try:
        return subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True, text=True,
                              timeout=10).stdout.strip()
    except OSError:
        return ""


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolution", type=int, default=30, help="particles per H (dx = H / resolution)")
    ap.add_argument("--model", help="physics.model (default: none given, the scene default)")
    ap.add_argument("--backend", default="numba")
    ap.add_argument("--out")
    args = ap.parse_args()
    scene = default_scene(args.resolution, args.model)
    rows, info = run(scene, args.backend)
    t_star = np.array([r["t_star"] for r in rows])
    p_star = np.array([r["p_star"] for r in rows])
    metrics = buchner.errors(t_star, p_star)
    result = {
        "case": "Buchner 2002 dam break, H = 0.6 m, only geometry, sound speed and time.end given",
        "model": scene["physics.model"], "model_given": bool(args.model), "resolution": args.resolution,
        "spacing": scene["fluid.spacing"], "particles": info["particles"], "t_end_star": T_END_STAR,
        "reached_end": bool(info["error"] is None and t_star[-1] >= T_END_STAR * (1 - 1e-9)),
        "t_star_reached": float(t_star[-1]), "error": info["error"], "steps": info["steps"],
        "mean_dt": float(rows[-1]["t"] / max(info["steps"], 1)), "wall_s": info["wall_s"], "device": info["device"],
        "max_p_star": float(np.nanmax(p_star)),
        "p1": {k: metrics[k] for k in ("peak_t_star", "peak_p_star", "peak_t_star_measured", "peak_p_star_measured",
                                        "rms_p_star", "rms_p_star_smoothed", "meets")},
        "scene": json.loads(scene.to_json()),
        "host": {"platform": platform.platform(), "cpu_count": os.cpu_count()},
        "versions": {"python": platform.python_version(), "numpy": np.__version__, "numba": numba.__version__},
        "commit": commit(),
    }
    print(json.dumps({k: v for k, v in result.items() if k not in ("scene", "host", "versions")}, indent=1))
    out = Path(args.out or ROOT / "benchmarks" / "results" / f"default_model_{result['model']}_H{args.resolution}.json")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({**result, "samples": rows}, indent=1) + "\n")
    print(f"wrote {out}")
    return 0 if result["reached_end"] else 1


if __name__ == "__main__":
    raise SystemExit(main())
