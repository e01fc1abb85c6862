"""The 2D dam break of Zhou et al. (1999) and Buchner (2002) at MARIN: the impact pressure on the
downstream wall at sensor P1, against the measured series.

Geometry (metres; x along the tank, y up): a column H = 0.6 high and 2H = 1.2 wide against the
left wall of a tank 3.22 long (5.366 H), released at t = 0; P1 on the right wall, x = 3.22,
y = 0.16 (the data header; TrixiParticles' validation/dam_break_2d takes the sensor's top edge
there, the transducer being 9 mm across). The tank is 4.0 high, as in TrixiParticles'
examples/fluid/dam_break_2d.jl: the jet that climbs the right wall must not reach the ceiling.

Dimensionless as the data: t* = t sqrt(g / H), p* = p / (rho_0 g H). The measured series
(validation/data/buchner2002_P1_trixi.csv, as TrixiParticles extracted it from Buchner's thesis)
starts at t* = 2.03, before the surge arrives (t* about 2.45).

Sensor: sphcore.validate.sensors.wall_pressure at P1 (Shepard-normalised kernel sum on the wall,
its images counted; that module says why on the wall). A sample is one instant, every
SAMPLE_DT_STAR in t*: raw, not a running mean.

Metrics (issue 12's targets):
- the impact peak: the largest sample for t* in IMPACT_WINDOW, its time and height against the
  measured series' (2.774, 0.687): time within 5 %, height within 20 %;
- the RMS of simulated minus measured p* at the measured times with 0 <= t* <= RMS_UNTIL (the
  simulation linearly interpolated there): at most 0.1.
The same of the running mean over SMOOTH_STAR (a transducer's area and the digitisation both
smooth) are given beside them, not in place of them.

Peers (PEERS; the summary's "peers", the plot's thin lines): the same metrics of TrixiParticles'
own WCSPH results at this sensor and of Marrone et al. 2011's delta-SPH curves, at H/40, H/80 and
H/320, and of De Courcy et al. 2024's incompressible delta-SPH at H/400. TrixiParticles' reach RMS
0.27-0.32 and rise as slowly after the impact as ours, De Courcy's 0.34; Marrone's 0.16-0.19.

A simulated reference (REFERENCE; the summary's "reference", the plot's lower panels): De Courcy et
al. 2024's series at four heights on the same wall, their P4 at P1's. A code that solves the same
equations should follow it, whatever the measured series does: the RMS of our samples minus theirs
at their times (t* 2.4-7), the same to t* = CALM_UNTIL (before the plunging wave falls back and both
series turn to noise), and each sensor's impact peak beside theirs.

Model: linear equation of state at c = 20 sqrt(g H) (48.5 m/s, as TrixiParticles; 10 times the
fastest flow, 2 sqrt(g H)), h = 2 dx, viscosity alpha = 0.02 (as Monaghan's alpha, or Mueller's
mu = alpha rho_0 c h / (2 dim + 4) in the laminar model), the rest from the named configuration
(sphcore.validate.configs).
"""
import csv
import io
import json
import math
import textwrap
import time
from pathlib import Path

import numpy as np

from tqdm import tqdm

from sphcore.errors import SimulationError
from sphcore.output import atomic_savefig, atomic_write_bytes
from sphcore.scene import Scene, SceneError, stable_dt
from sphcore.signals import Interrupted, Signals
from sphcore.validate import DATA_DIR, configs, sensors
from sphcore.validate.files import read_csv, read_json
from sphcore.validate.sensors import wall_pressure

G = 9.81
RHO0 = 1000.0
TANK_LENGTH = 5.366  # in units of H: 3.22 m
TANK_HEIGHT = 4.0  # m
SENSOR_Y = 0.16  # m: P1
DATA_FILE = "buchner2002_P1_trixi.csv"
SAMPLE_DT_STAR = 0.01  # t* between samples
IMPACT_WINDOW = (2.0, 4.0)  # t*: the first impact (the data's second peak, the plunging wave, comes at 5.8)
RMS_UNTIL = 7.0  # t*
CALM_UNTIL = 6.0  # t*: the plunging wave falls back onto the flow after this
SMOOTH_STAR = 0.1  # t*: the running mean reported beside the raw samples
TARGETS = {"peak_time": 0.05, "peak_height": 0.20, "rms": 0.1}  # issue 12

# Peers on the same case and sensor, digitised or taken from their own reference results (each file's
# header names its source): {label: (file, {column label: column})}. Their metrics are computed as ours.
PEERS = {"TrixiParticles WCSPH": ("buchner2002_P1_trixiparticles_wcsph.csv", {"H/40": 1, "H/80": 2, "H/320": 3}),
         "Marrone et al. 2011 delta-SPH": ("buchner2002_P1_marrone2011_trixi.csv", {"H/40": 1, "H/80": 2, "H/320": 3}),
         "De Courcy et al. 2024 delta-SPH": ("decourcy2024_P4_trixi.csv", {"H/400": 1})}
# De Courcy et al. 2024's simulation at four heights on the right wall: {sample column: (y of the
# sensor's centre in m, file)}; their P4 is P1 (the column p_star).
REFERENCE = {"p_star_6mm": (0.006, "decourcy2024_P1_trixi.csv"), "p_star_30mm": (0.030, "decourcy2024_P2_trixi.csv"),
             "p_star_60mm": (0.060, "decourcy2024_P3_trixi.csv"), "p_star": (SENSOR_Y, "decourcy2024_P4_trixi.csv")}

SETTINGS = {  # what `sphcore validate dam-break-pressure` runs
    "resolution": 40,  # particles per H
    "H": 0.6,  # m
    "t_end_star": 7.3,  # t*: the data's last sample
    "backend": "numba",
    "device": None,
    "precision": "float32",
    "config": configs.DEFAULT_CONFIG,
    "equation_of_state": "linear",
    "sound_speed": 20.0,  # in units of sqrt(g H)
    "alpha": 0.02,
    "smoothing_ratio": 2.0,
    "dt_fraction": 1.0,
    **{option: None for option in configs.OPTIONS},  # a switch laid over the configuration
}


def read_measured():
    """(t*, p*) of the measured series and its header line."""
    path = DATA_DIR / DATA_FILE
    header = path.open(encoding="utf-8").readline().lstrip("# ").strip()
    data = np.loadtxt(path, delimiter=",", comments="#", ndmin=2)
    return data[:, 0], data[:, 1], header


def read_peers():
    """{"<peer> <resolution>": (t*, p*)} of PEERS."""
    out = {}
    for peer, (name, columns) in PEERS.items():
        data = np.loadtxt(DATA_DIR / name, delimiter=",", comments="#", ndmin=2)
        for label, column in columns.items():
            out[f"{peer} {label}"] = (data[:, 0], data[:, column])
    return out


def read_reference():
    """{sample column: (t*, p*)} of REFERENCE."""
    out = {}
    for column, (_, name) in REFERENCE.items():
        data = np.loadtxt(DATA_DIR / name, delimiter=",", comments="#", ndmin=2)
        out[column] = (data[:, 0], data[:, 1])
    return out


def reference_errors(rows):
    """{sample column: metrics} of the sampled rows against REFERENCE: the RMS of ours minus theirs at
    their times up to RMS_UNTIL, and the impact peaks (IMPACT_WINDOW) of both."""
    t = np.array([r["t_star"] for r in rows])
    out = {}
    for column, (t_ref, p_ref) in read_reference().items():
        p = np.array([r[column] for r in rows])
        rms, count = rms_against(t, p, t_ref, p_ref)
        (pt, pp), (pt_ref, pp_ref) = impact_peak(t, p), impact_peak(t_ref, p_ref)
        out[column] = {"y": REFERENCE[column][0], "rms_p_star": rms, "rms_points": count,
                       "rms_p_star_calm": rms_against(t, p, t_ref, p_ref, CALM_UNTIL)[0], "peak_t_star": pt,
                       "peak_p_star": pp, "reference_peak_t_star": pt_ref, "reference_peak_p_star": pp_ref}
    return out


def peer_errors():
    """{"<peer> <resolution>": the metrics of errors()} of each peer series against the measured one."""
    return {label: {k: v for k, v in errors(t, p).items() if k not in ("targets", "peak_t_star_measured",
                                                                       "peak_p_star_measured")}
            for label, (t, p) in read_peers().items()}


def buchner_scene(settings=None):
    """The Scene of `settings` (SETTINGS overridden, the configuration's keys laid over it)."""
    s = {**SETTINGS, **(settings or {})}
    H = s["H"]
    if not (isinstance(s["resolution"], int) and s["resolution"] >= 4):
        raise SceneError(f"resolution = {s['resolution']!r}: particles per H, an integer >= 4")
    dx = H / s["resolution"]
    c = s["sound_speed"] * math.sqrt(G * H)
    h = s["smoothing_ratio"] * dx
    data = {
        "name": "dam_break_pressure",
        "physics": {"model": "graphics", "dimension": 2, "equation_of_state": s["equation_of_state"],
                    "precision": s["precision"]},  # the configuration's keys are laid over the graphics model
        "domain": {"box_min": [0.0, 0.0], "box_max": [TANK_LENGTH * H, TANK_HEIGHT]},
        "fluid": {"blocks": [{"min": [0.0, 0.0], "max": [2 * H, H]}], "spacing": dx,
                  "smoothing_ratio": s["smoothing_ratio"], "stiffness": c * c,
                  "viscosity": s["alpha"] * RHO0 * c * h / 8.0},
        "forces": {"gravity": [0.0, -G]},
        "time": {"dt": "auto", "dt_fraction": s["dt_fraction"], "steps": 1},
    }
    configs.apply(data, configs.overrides(s))
    return Scene.from_dict(data, source="dam break pressure (Buchner 2002)")


def dt_estimate(scene):
    """The time step to plan the sampling with: the scene's, or its stability bound where the
    step is chosen on the device (time.dt = "adaptive")."""
    dt = scene["time.dt"]
    if isinstance(dt, (int, float)):
        return float(dt)
    if dt == "auto":
        return scene.dt
    return scene["time.dt_fraction"] * stable_dt(scene, scene.speed_estimate())[0]


def sample_run(scene, backend, t_end, sample_dt, sample, progress=True, desc="", device=None):
    """Step `scene` to t_end, calling sample(state, t) -> dict at t = 0 and about every sample_dt
    of simulated time (Simulation.time, the sum of the steps); return (rows, info): info has the
    particles, steps, stepping seconds (wall_s), the device, the error that stopped the run (None if it
    ran to the end) and the signal that did (SIGINT or SIGTERM: the run stops at the next sample, or at
    once on a second signal; None), so that the caller writes what was sampled, then raises `stop(info)`."""
    from sphcore.simulation import Simulation  # (numba: loaded where a run starts)

    every = max(1, round(sample_dt / dt_estimate(scene)))
    options = {"device": device} if backend == "vulkan" and device is not None else {}
    sim = Simulation(scene, backend, **options)
    rows, wall, error, signum = [], 0.0, None, None
    try:
        with Signals() as signals, tqdm(total=round(t_end, 6), unit="s", disable=not progress, desc=desc,
                                        bar_format="{l_bar}{bar}| {n:.3f}/{total:.3f} s [{elapsed}<{remaining}]") as bar:
            while True:
                t = sim.time
                rows.append(sample(sim.read(), t))
                if t >= t_end * (1 - 1e-9):
                    break
                start = time.perf_counter()
                advance(sim, signals, every)
                wall += time.perf_counter() - start
                bar.update(min(sim.time, t_end) - bar.n)
    except SimulationError as e:
        error = str(e)
    except Interrupted as e:
        error, signum = str(e), e.signum
    finally:
        device_name = sim.device_name
        sim.close()
    return rows, {"particles": sim.n, "steps": sim.step_count, "wall_s": wall, "device": device_name,
                  "error": error, "signal": signum}


def advance(sim, signals, steps):
    """sim.advance(steps) at a safe point of a validation run's loop: a signal received since the last
    one stops the run here (Interrupted, naming the time), one during the steps stops them at once."""
    signals.poll(f"at t = {sim.time:.6g} s")
    signals.stepping = True
    try:
        sim.advance(steps)
    finally:
        signals.stepping = False


def sampled_run(sim, sample, steps, every, desc, progress, t_end=None):
    """Sample a run, rows.append(sample(sim)), at the start and every `every` steps up to `steps` steps (with t_end,
    an adaptive dt's run: up to t_end in simulated time), stepping at safe points (buchner.advance) under a progress
    bar: (rows, wall seconds stepping, error, signal). A blow-up or a signal ends the run with the rows it has."""
    rows, wall, error, signum = [], 0.0, None, None
    try:
        with Signals() as signals, tqdm(total=steps, unit="step", disable=not progress, desc=desc) as bar:
            while True:
                rows.append(sample(sim))
                if sim.step_count >= steps if t_end is None else sim.time >= t_end * (1 - 1e-9):
                    break
                k = min(every, steps - sim.step_count) if t_end is None else every
                start = time.perf_counter()
                advance(sim, signals, k)  # both backends return when the steps are done
                wall += time.perf_counter() - start
                bar.update(k)
    except SimulationError as e:
        error = str(e)
    except Interrupted as e:
        error, signum = str(e), e.signum
    return rows, wall, error, signum


def stop(info, out_dir=None, reached=""):
    """The exception that ends a validation run that stopped early, once it wrote its samples (to `reached`,
    e.g. "t = 1.2 s", in out_dir where given): Interrupted where a signal stopped it (the shell's status is
    then 128 + the signal), else SimulationError."""
    message = info["error"] + (f"; the samples to {reached} are in {out_dir}" if out_dir is not None else "")
    return Interrupted(info["signal"], message) if info.get("signal") else SimulationError(message)


# ---- metrics ----

def impact_peak(t_star, p_star, window=IMPACT_WINDOW):
    """(t*, p*) of the largest sample with t* in `window` (NaN, NaN if none)."""
    t_star, p_star = np.asarray(t_star, float), np.asarray(p_star, float)
    use = (t_star >= window[0]) & (t_star <= window[1]) & np.isfinite(p_star)
    if not use.any():
        return math.nan, math.nan
    k = np.flatnonzero(use)[np.argmax(p_star[use])]
    return float(t_star[k]), float(p_star[k])


def rms_against(t_sim, p_sim, t_exp, p_exp, until=RMS_UNTIL):
    """(RMS, count): simulated minus measured p* at the measured times t_exp in [0, until] that
    the simulation covers, the simulation interpolated linearly there."""
    t_sim, p_sim = np.asarray(t_sim, float), np.asarray(p_sim, float)
    t_exp, p_exp = np.asarray(t_exp, float), np.asarray(p_exp, float)
    use = (t_exp >= 0) & (t_exp <= until) & (t_exp >= t_sim[0]) & (t_exp <= t_sim[-1])
    if not use.any():
        return math.nan, 0
    diff = np.interp(t_exp[use], t_sim, p_sim) - p_exp[use]
    return float(np.sqrt(np.mean(diff ** 2))), int(use.sum())


def running_mean(t, values, width=SMOOTH_STAR):
    """The mean of `values` over a window of about `width` (in t*) centred on each sample (sensors.running_mean)."""
    return sensors.running_mean(np.asarray(t, float), np.asarray(values, float), width)


def errors(t_star, p_star):
    """The metrics of a simulated series (t*, p*) against the measured one, and whether each
    meets issue 12's target."""
    t_exp, p_exp, _ = read_measured()
    pt_exp, pp_exp = impact_peak(t_exp, p_exp)
    out = {"peak_t_star_measured": pt_exp, "peak_p_star_measured": pp_exp}
    series = {"": p_star}
    if len(t_star) > 1:
        series["_smoothed"] = running_mean(t_star, p_star)
    for suffix, p in series.items():
        pt, pp = impact_peak(t_star, p)
        rms, count = rms_against(t_star, p, t_exp, p_exp)
        out.update({f"peak_t_star{suffix}": pt, f"peak_p_star{suffix}": pp,
                    f"peak_time_error{suffix}": (pt - pt_exp) / pt_exp, f"peak_height_error{suffix}": (pp - pp_exp) / pp_exp,
                    f"rms_p_star{suffix}": rms, f"rms_points{suffix}": count})
    out["targets"] = TARGETS
    out["meets"] = {"peak_time": bool(abs(out["peak_time_error"]) <= TARGETS["peak_time"]),
                    "peak_height": bool(abs(out["peak_height_error"]) <= TARGETS["peak_height"]),
                    "rms": bool(out["rms_p_star"] <= TARGETS["rms"])}
    return out


# ---- the run ----

def run_buchner(settings=None, out_dir=None, progress=True):
    """Run the case; return (rows, summary). rows: t, t_star, p_star per sample. Writes
    dam_break_pressure.csv and .json to out_dir if given; a run that blows up or is interrupted writes what
    it has (the summary names the error) and raises SimulationError or Interrupted (`stop`)."""
    s = {**SETTINGS, **(settings or {})}
    scene = buchner_scene(s)
    H = s["H"]
    scale = math.sqrt(G / H)
    sensor = (TANK_LENGTH * H, SENSOR_Y)
    lo, hi = scene["domain.box_min"], scene["domain.box_max"]

    def sample(state, t):
        row = {"t": t, "t_star": t * scale}
        for column, (y, _) in sorted(REFERENCE.items(), key=lambda item: item[1][0] != SENSOR_Y):  # p_star first
            p = wall_pressure(state["particle_x"], state["particle_p"], (sensor[0], y), scene.h, lo, hi)
            row[column] = p / (RHO0 * G * H)
        return row

    rows, info = sample_run(scene, s["backend"], s["t_end_star"] / scale, SAMPLE_DT_STAR / scale, sample,
                            progress, f"dam break pressure [{s['backend']}]", s.get("device"))
    summary = {"settings": s, "configuration": configs.overrides(s), **info, "dt": dt_estimate(scene), "h": scene.h,
               "sensor": sensor, **errors([r["t_star"] for r in rows], [r["p_star"] for r in rows]),
               "peers": peer_errors(), "reference": reference_errors(rows)}
    summary["rms_p_star_reference"] = summary["reference"]["p_star"]["rms_p_star"]
    summary["rms_p_star_reference_calm"] = summary["reference"]["p_star"]["rms_p_star_calm"]
    if out_dir is not None:
        write_results(rows, summary, out_dir)
    if info["error"]:
        if out_dir is not None:
            try:
                plot(rows, summary, Path(out_dir) / "dam_break_pressure.png")
            except ImportError:  # no matplotlib (the GPU machine): the CSV and JSON are there
                pass
        raise stop(info, out_dir, f"t* = {rows[-1]['t_star']:.4g}")
    return rows, summary


def read_results(out_dir, name="dam_break_pressure"):
    """(rows, summary) as write_results wrote them."""
    out = Path(out_dir)
    return read_csv(out / f"{name}.csv", numbers="all"), read_json(out / f"{name}.json")


def clean(value):
    if isinstance(value, dict):
        return {k: clean(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [clean(v) for v in value]
    return None if isinstance(value, float) and not math.isfinite(value) else value


def write_results(rows, summary, out_dir, name="dam_break_pressure"):
    """DIR/<name>.csv and .json, each written whole or not at all."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(rows[0]), lineterminator="\n")
    writer.writeheader()
    for r in rows:
        writer.writerow({k: f"{v:.6g}" for k, v in r.items()})
    atomic_write_bytes(out / f"{name}.csv", buf.getvalue().encode())
    atomic_write_bytes(out / f"{name}.json", json.dumps(clean(summary), indent=1).encode())


def plot(rows, summary, path):
    """p*(t*) at P1: each sample, its running mean, the measured series and the peers'; below, every
    sensor beside De Courcy et al.'s simulation (REFERENCE); as a PNG."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t_exp, p_exp, header = read_measured()
    t = np.array([r["t_star"] for r in rows])
    p = np.array([r["p_star"] for r in rows])
    fig = plt.figure(figsize=(11, 7.4), dpi=110)
    grid = fig.add_gridspec(2, len(REFERENCE), height_ratios=(1.6, 1))
    ax = fig.add_subplot(grid[0, :])
    ax.plot(t, p, color="0.6", lw=0.6, label="sphcore, each sample")
    if len(t) > 1:
        ax.plot(t, running_mean(t, p), "k-", lw=1.2, label=f"sphcore, running mean over {SMOOTH_STAR:g}")
    peers = summary.get("peers") or {}
    for (label, (tp, pp)), color in zip(read_peers().items(), ("tab:blue", "tab:cyan", "tab:purple", "tab:green",
                                                                 "tab:olive", "tab:orange", "tab:brown")):
        if label.endswith(("H/40", "H/320", "H/400")):  # the coarsest and finest of each peer
            rms = peers.get(label, {}).get("rms_p_star", math.nan)
            ax.plot(tp, pp, "-", color=color, lw=0.8, alpha=0.8, label=f"{label} (RMS {rms:.3f})")
    ax.plot(t_exp, p_exp, "o", color="tab:red", ms=3.5, mfc="none", label="Buchner 2002 (P1, as TrixiParticles extracted it)")
    ax.plot([summary["peak_t_star"]], [summary["peak_p_star"]], "kv", ms=7, label="simulated impact peak")
    ax.set(xlabel="t* = t sqrt(g/H)", ylabel="p* = p / (rho g H)", xlim=(0, max(t[-1], 1.0)),
           ylim=(-0.1, max(1.5, 1.3 * float(np.nanmax(p_exp)), min(3.0, 1.1 * float(np.nanmax(p, initial=0))))))
    s = summary["settings"]
    ax.set_title(f"P1 (y = {SENSOR_Y} m): peak t* {summary['peak_t_star']:.3f} ({100 * summary['peak_time_error']:+.1f} %), "
                 f"p* {summary['peak_p_star']:.3f} ({100 * summary['peak_height_error']:+.0f} %); "
                 f"RMS {summary['rms_p_star']:.3f} (running mean {summary.get('rms_p_star_smoothed', math.nan):.3f})",
                 fontsize=9)
    fig.suptitle(textwrap.fill(f"2D dam break (Buchner 2002), {summary['particles']} particles (H/{s['resolution']}), "
                               f"configuration {s['config']}: {configs.describe(summary['configuration'])}; {s['backend']}",
                               150), fontsize=8)
    ax.legend(fontsize=7, loc="upper right")
    ax.grid(True, lw=0.3, alpha=0.5)
    reference, metrics = read_reference(), summary.get("reference") or {}
    for k, column in enumerate(sorted(REFERENCE, key=lambda c: REFERENCE[c][0])):
        sub = fig.add_subplot(grid[1, k])
        if column in rows[0]:
            sub.plot(t, [r[column] for r in rows], color="0.4", lw=0.6, label="sphcore")
        sub.plot(*reference[column], color="tab:brown", lw=0.9, label="De Courcy et al. 2024")
        y, m = REFERENCE[column][0], metrics.get(column, {})
        sub.set(xlim=(2.0, 7.2), xlabel="t*", title=f"y = {1000 * y:g} mm: RMS {m.get('rms_p_star', math.nan):.3f} "
                                                    f"({m.get('rms_p_star_calm', math.nan):.3f} to t* {CALM_UNTIL:g})")
        sub.title.set_fontsize(8)
        sub.tick_params(labelsize=7)
        sub.grid(True, lw=0.3, alpha=0.5)
        if k == 0:
            sub.set_ylabel("p*")
            sub.legend(fontsize=7)
    fig.tight_layout()
    atomic_savefig(fig, path)
    plt.close(fig)
    return path
