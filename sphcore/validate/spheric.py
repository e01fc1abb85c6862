"""SPHERIC benchmark test 2 (Issa & Violeau 2006): the 3D dam break of Kleefsman et al. (2005,
J. Comput. Phys. 206, 363-393; experiment at MARIN) hitting a box on the floor. Water heights H1-H4
and pressures P1-P8 against the measured series.

`sphcore validate spheric --out DIR` writes DIR/spheric_test2.csv (t, H1..H4 in m, P1..P8 in Pa,
every SAMPLE_DT), DIR/spheric_test2.json (settings, RMS of each series against the experiment over
t <= 6 s or the run's end, particles, wall time, device) and DIR/spheric_test2.png.

Geometry, in metres. Here y is up and z across the tank (the papers' y and z swapped, so that
gravity is -y as in every scene of this project); x runs along the tank from the wall the box
stands near. Tank 3.22 x 1 x 1; water 1.228 long, 0.55 high and 1 wide against the far wall
(x = 1.992 .. 3.22), released at t = 0; box 0.161 along x (0.6635 .. 0.8245), 0.161 high, 0.403
across, centred. On the tank's centre line z = 0.5: height gauges H1 at x = 0.496 (in the box's
shadow), H2 at 0.992, H3 at 1.488, H4 at 2.638 (in the reservoir, so it starts at 0.55 m);
pressure sensors P1-P4 on the box's face toward the water (x = 0.8245) at y = 0.021, 0.061, 0.101,
0.141 and P5-P8 on its top (y = 0.161) at x = 0.8035, 0.7635, 0.7235, 0.6835.
Sources: Lethe's model of this case (github.com/chaos-polymtl/lethe, examples/multiphysics/
3d-dam-break: tank_with_obstacle.geo for tank, box and water, 3d-dam-break_postprocess.py for the
gauges) and AQUAgpusph's (github.com/sanguinariojoe/aquagpusph, examples/3D/
spheric_testcase2_dambreak/cMake/Create.py: the same box; the sensors 0.021 m + 0.04 m steps from
the box's front bottom edge, up the face and along the top).

The measured file (validation/data/spheric_test2_kleefsman2005_P1-P8_H1-H4.csv, AQUAgpusph's copy
of the SPHERIC data) labels its height columns H1, H2, H3, H4, but they hold H3, H2, H1, H4: Lethe
and AQUAgpusph both read them in that order, and the arrival times say so too: the first column
is wetted at 0.19 s, the second at 0.36 s, the third at 0.92 s, as a front leaving x = 1.992
reaches x = 1.488, then 0.992, and last 0.496 behind the box. The pressure columns are P1..P8.

Height: the water volume above the gauge per unit floor area, sum_j dx^3 W2(r_j), r_j the
horizontal distance of particle j from the gauge and W2 the 2D poly6 kernel of radius h (which
integrates to 1 over the plane): the colour field integrated along the vertical. Each particle
stands for a cube dx^3. A layer of depth D gives D (to the kernel's lattice sum, within 1.5 %),
without a threshold on neighbour counts or density; spray above the gauge counts with its
volume, not with its height.
Pressure: the SPH interpolation of the particles' pressure at the sensor, Shepard-normalised,
sum_j p_j W(r_j) / sum_j W(r_j) with the 3D poly6 kernel of radius h (equal masses and densities
near rho_0, so the volumes cancel): the sensor sits on the box's face with fluid on one side only,
and the normalisation makes the average of a linear field exact there. No particle within h: 0
(dry, as the experiment's sensors read at rest). A sample is one instant: the weakly compressible
pressure carries the sound waves of every impact (c^2 times a 1 % density error is 16 kPa), so
the JSON gives each sensor's RMS also for the running mean over SMOOTH_S, and the plot draws both.

Model: Tait equation of state with c = 40 m/s (10 times sqrt(2 g 0.55), the fastest free-fall
speed, as in AQUAgpusph's setup), viscosity mu = alpha rho_0 c h / (2 dim + 4) with alpha = 0.02
as in the 2D dam break (sphcore.validate.dam_break), walls and box free-slip mirror images,
dt = "auto" at half the stability bound: at dx = 0.02 m and the whole bound, the H200 runs blew
up (a particle flung at over 100 m/s, at t = 2.3 s and, before images were kept to the solid,
at 4.4 s); at half of it they run the 6 s (so does dx = 0.01 m at the whole bound). The GPU
runs committed in validation/results/ are reproduced by benchmarks/spheric_gpu.sh.
"""
import csv
import io
import json
import math
import time
from pathlib import Path

import numpy as np


from sphcore.paths import SCENE_DIR
from sphcore.scene import Scene
from sphcore.validate import DATA_DIR, configs, sensors
from sphcore.validate.buchner import dt_estimate, sampled_run, stop
from sphcore.validate.files import read_csv, read_json

G = 9.81
TANK = (3.22, 1.0, 1.0)  # x along, y up, z across
WATER = (1.228, 0.55, 1.0)  # against the far wall x = 3.22
BOX_MIN = (0.6635, 0.0, 0.5 - 0.403 / 2)
BOX_MAX = (0.8245, 0.161, 0.5 + 0.403 / 2)
GAUGES = {"H1": 0.496, "H2": 0.992, "H3": 1.488, "H4": 2.638}  # x of each height gauge, on z = 0.5
SENSORS = {  # (x, y, z) of each pressure sensor
    **{f"P{k + 1}": (BOX_MAX[0], 0.021 + 0.04 * k, 0.5) for k in range(4)},
    **{f"P{k + 5}": (BOX_MAX[0] - 0.021 - 0.04 * k, BOX_MAX[1], 0.5) for k in range(4)},
}
DATA_FILE = "spheric_test2_kleefsman2005_P1-P8_H1-H4.csv"
# gauge -> the column of DATA_FILE (0 = t) that holds it: the file's height columns are H3, H2, H1, H4
DATA_COLUMNS = {**{f"P{k}": k for k in range(1, 9)}, "H3": 9, "H2": 10, "H1": 11, "H4": 12}
OBSTACLE_MESH = SCENE_DIR / "meshes" / "spheric_box.stl"  # the box as a closed surface (scenes/meshes/make_meshes.py)
SAMPLE_DT = 0.01  # s between samples
SMOOTH_S = 0.1  # s: the running mean of the pressures that the JSON and the plot give beside each sample
RMS_UNTIL = 6.0  # s: the errors are taken over t <= this (or the run's end)

SETTINGS = {  # what `sphcore validate spheric` runs
    "spacing": 0.02,  # m: about 85,000 particles
    "t_end": 6.0,  # s
    "backend": "numba",
    "precision": "float32",
    "stiffness": 1600.0,  # m^2/s^2: c = 40 m/s
    "alpha": 0.02,  # viscosity mu = alpha rho_0 c h / (2 dim + 4)
    "smoothing_ratio": 2.0,
    "dt_fraction": 0.5,  # of the stability bound (dt = "auto"): the whole bound blew up (module docstring)
    "obstacle": "box",  # box: domain.obstacles (mirror images); mesh: the same box as a body from OBSTACLE_MESH
    "config": configs.DEFAULT_CONFIG,  # the model (sphcore.validate.configs); the switches below override it
    **{option: None for option in configs.OPTIONS},
}


def spheric_scene(settings=None):
    """The Scene of `settings` (SETTINGS overridden). The water block is whole particles, the
    nearest to the experiment's 1.228 x 0.55 x 1 m, flush with the far wall and the floor."""
    s = {**SETTINGS, **(settings or {})}
    dx = s["spacing"]
    n = [max(1, round(w / dx)) for w in WATER]
    h = s["smoothing_ratio"] * dx
    viscosity = s["alpha"] * 1000.0 * math.sqrt(s["stiffness"]) * h / 10.0
    box = s["obstacle"] == "box"
    return Scene.from_dict(configs.apply({
        "name": "spheric_test2",
        "physics": {"model": "graphics", "dimension": 3, "equation_of_state": "tait", "precision": s["precision"]},
        "domain": {"box_min": [0.0, 0.0, 0.0], "box_max": list(TANK),
                   "obstacles": [{"min": list(BOX_MIN), "max": list(BOX_MAX)}] if box else []},
        "bodies": [] if box else [{"name": "box", "mesh": str(OBSTACLE_MESH)}],
        "fluid": {"blocks": [{"min": [TANK[0] - n[0] * dx, 0.0, 0.0], "max": [TANK[0], n[1] * dx, min(n[2] * dx, TANK[2])]}],
                  "spacing": dx, "smoothing_ratio": s["smoothing_ratio"], "stiffness": s["stiffness"],
                  "viscosity": viscosity},
        "forces": {"gravity": [0.0, -G, 0.0]},
        "time": {"dt": "auto", "dt_fraction": s["dt_fraction"], "steps": 1},
    }, configs.overrides(s)), source="SPHERIC test 2 (Kleefsman et al. 2005)")


def water_heights(x, dx, h):
    """{gauge: water height [m]}: the volume above the gauge per unit area (module docstring)."""
    out = {}
    for name, gx in GAUGES.items():
        r2 = (x[:, 0] - gx) ** 2 + (x[:, 2] - 0.5) ** 2
        q = np.clip(h * h - r2, 0.0, None)
        out[name] = float(dx ** 3 * 4.0 / (math.pi * h ** 8) * (q ** 3).sum())
    return out


def pressures(x, p, h):
    """{sensor: pressure [Pa]}: Shepard-normalised SPH interpolation at each sensor, 0 where dry."""
    out = {}
    for name, s in SENSORS.items():
        q = np.clip(h * h - ((x - np.asarray(s)) ** 2).sum(axis=1), 0.0, None) ** 3
        total = q.sum()
        out[name] = float((q * p).sum() / total) if total > 0 else 0.0
    return out


def obstacle_force(sim):
    """{Fx, Fy, Fz: the fluid's force on the box [N]} where it is a body (obstacle "mesh"): m sum a over its wall
    particles, as a force gauge sums it (sphcore/gauges.py); {} for the box of mirror images, which has none."""
    if sim.n == sim.fluid_count:
        return {}
    force = sim.scene.mass * sim.walls["particle_a"].astype(np.float64).sum(axis=0)
    return dict(zip(("Fx", "Fy", "Fz"), map(float, force)))


def read_experiment():
    """(t, {gauge: series}) of the measured file, the gauges named as in GAUGES and SENSORS."""
    data = np.loadtxt(DATA_DIR / DATA_FILE, delimiter=",", comments="#", ndmin=2)
    return data[:, 0], {name: data[:, col] for name, col in DATA_COLUMNS.items()}


def running_mean(t, values, width=SMOOTH_S):
    """The mean of `values` over a window of about `width` [s] centred on each sample (sensors.running_mean)."""
    return sensors.running_mean(t, values, width)


def errors(rows):
    """{rms_<gauge>: RMS of simulated minus measured over the samples with t <= RMS_UNTIL}, with
    the measured series interpolated at the simulated times (it is sampled every millisecond);
    for the pressures also rms_<sensor>_smoothed, both series as their running means over SMOOTH_S."""
    t_exp, exp = read_experiment()
    t = np.array([r["t"] for r in rows])
    use = t <= min(RMS_UNTIL, t_exp[-1])
    out = {"rms_until_s": float(t[use][-1]) if use.any() else 0.0}
    for name in list(GAUGES) + list(SENSORS):
        sim, measured = np.array([r[name] for r in rows]), np.interp(t, t_exp, exp[name])
        out[f"rms_{name}"] = float(np.sqrt(np.mean((sim[use] - measured[use]) ** 2)))
        if name in SENSORS:
            smooth = running_mean(t, sim) - np.interp(t, t_exp, running_mean(t_exp, exp[name]))
            out[f"rms_{name}_smoothed"] = float(np.sqrt(np.mean(smooth[use] ** 2)))
    return out


def run_spheric(settings=None, out_dir=None, progress=True):
    """Run the case; return (rows, summary). rows: one dict per sample (t, H1..H4, P1..P8).
    Writes spheric_test2.csv and spheric_test2.json to out_dir if given; a run that blows up or is
    interrupted (SIGINT, SIGTERM) writes the samples it has (the summary names the error), then raises
    SimulationError or Interrupted (buchner.stop)."""
    from sphcore.simulation import Simulation  # (numba: loaded where a run starts)

    s = {**SETTINGS, **(settings or {})}
    scene = spheric_scene(s)
    dt, dx, h = dt_estimate(scene), scene["fluid.spacing"], scene.h
    every = max(1, round(SAMPLE_DT / dt))
    steps = math.ceil(s["t_end"] / dt)
    adaptive = scene["time.dt"] == "adaptive"  # the device chooses each step: run to t_end in simulated time
    options = {"device": s.get("device")} if s["backend"] == "vulkan" else {}
    start = time.perf_counter()
    sim = Simulation(scene, s["backend"], **options)

    def sample(sim):
        state = sim.read()
        x, p = state["particle_x"].astype(np.float64), state["particle_p"].astype(np.float64)
        return {"t": sim.time, **water_heights(x, dx, h), **pressures(x, p, h), **obstacle_force(sim)}

    try:
        rows, wall, error, signum = sampled_run(sim, sample, steps, every, f"SPHERIC test 2 [{s['backend']}]",
                                                progress, s["t_end"] if adaptive else None)
    finally:
        device = sim.device_name
        sim.close()
    summary = {"settings": s, "configuration": configs.overrides(s), "particles": sim.n, "dt": dt,
               "steps": sim.step_count, "h": h, "viscosity": scene["fluid.viscosity"],
               "wall_s": wall, "total_s": time.perf_counter() - start, "device": device, "error": error,
               "signal": signum,
               "gauges_x": GAUGES, "sensors": SENSORS, **errors(rows)}
    if out_dir is not None:
        write_results(rows, summary, out_dir)
    if error:
        raise stop(summary, out_dir, f"t = {rows[-1]['t']:.4g} s")
    return rows, summary


def write_results(rows, summary, out_dir):
    """DIR/spheric_test2.csv and .json, each written whole or not at all."""
    from sphcore.output import atomic_write_bytes

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(rows[0]), lineterminator="\n")
    writer.writeheader()
    for r in rows:
        writer.writerow({k: f"{v:.6g}" for k, v in r.items()})
    atomic_write_bytes(out / "spheric_test2.csv", buf.getvalue().encode())
    atomic_write_bytes(out / "spheric_test2.json", json.dumps(summary, indent=1).encode())


def read_results(out_dir):
    """(rows, summary) as write_results wrote them (for plotting a run made elsewhere)."""
    out = Path(out_dir)
    return read_csv(out / "spheric_test2.csv", numbers="all"), read_json(out / "spheric_test2.json")


def plot(rows, summary, path):
    """Heights (top row) and pressures (two rows below) against the experiment, as a PNG."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from sphcore.output import atomic_savefig

    t_exp, exp = read_experiment()
    t = np.array([r["t"] for r in rows])
    force = "Fx" in rows[0]
    fig, axes = plt.subplots(4 if force else 3, 4, figsize=(15, 12 if force else 9), dpi=100)
    for ax, name in zip(axes.flat, list(GAUGES) + list(SENSORS)):
        sim = np.array([r[name] for r in rows])
        if name in GAUGES:
            ax.plot(t_exp, exp[name], color="tab:red", lw=0.7, label="Kleefsman et al. 2005")
            ax.plot(t, sim, "k-", lw=1.0, label="sphcore")
            ax.set_title(f"{name} at x = {GAUGES[name]:g} m: RMS {summary[f'rms_{name}']:.3g} m", fontsize=8)
        else:  # each sample in grey, its running mean in black (clipped: the acoustic spikes reach 30 kPa)
            ax.plot(t, sim, color="0.7", lw=0.5, label="sphcore, each sample")
            ax.plot(t_exp, running_mean(t_exp, exp[name]), color="tab:red", lw=1.0, label=f"experiment, {SMOOTH_S:g} s mean")
            ax.plot(t, running_mean(t, sim), "k-", lw=1.0, label=f"sphcore, {SMOOTH_S:g} s mean")
            ax.set_ylim(-500, 1.6 * max(exp[name].max(), 1000.0))
            ax.set_title("{} at ({:g}, {:g}) m: RMS {:.3g} kPa, of {:g} s means {:.3g} kPa".format(
                name, *SENSORS[name][:2], summary[f"rms_{name}"] / 1e3, SMOOTH_S, summary[f"rms_{name}_smoothed"] / 1e3),
                fontsize=7)
        unit = "m" if name in GAUGES else "Pa"
        ax.set_xlim(0, max(t[-1], 0.1))
        ax.tick_params(labelsize=7)
        ax.set_ylabel(f"{'height' if name in GAUGES else 'pressure'} [{unit}]", fontsize=7)
    if force:  # the fluid's force on the box (a body), each component
        for k, ax in zip("xyz", axes[3]):
            ax.plot(t, [r[f"F{k}"] for r in rows], "k-", lw=0.8)
            ax.set_title(f"F{k} on the box (its wall particles) [N]", fontsize=8)
            ax.tick_params(labelsize=7)
        axes[3, 3].axis("off")
    axes[0, 0].legend(fontsize=7)
    axes[1, 0].legend(fontsize=6)
    for ax in axes[-1]:
        ax.set_xlabel("t [s]", fontsize=7)
    s = summary["settings"]
    model = (f"Tait, c = {math.sqrt(s['stiffness']):g} m/s" if summary.get("configuration", {}).get(
        "physics.pressure_solver") != "dfsph" else "DFSPH")
    fig.suptitle(f"SPHERIC test 2, the box {'of mirror images' if s.get('obstacle', 'box') == 'box' else 'an STL body'}: "
                 f"{summary['particles']} particles (dx = {s['spacing']:g} m), {model}, "
                 f"{s['precision']}, {s['backend']} on {summary['device']}, {summary['wall_s']:.0f} s", fontsize=9)
    fig.tight_layout()
    atomic_savefig(fig, path)
    plt.close(fig)
    return path
