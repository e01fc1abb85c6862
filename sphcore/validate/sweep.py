"""The speed/accuracy sweep of the 2D dam break (issue 5): which settings buy how much accuracy
for how much time.

A point is a settings dict for `dam_break.run_dam_break`, varying the AXES below. The design is
not the full factorial: a resolution ladder around the defaults, crossed with the equation of
state, the time step and the viscosity (does the error shrink with resolution, and does that
depend on the model?), and every other axis one at a time at the default resolution. Points
are independent runs, executed through Dask's distributed scheduler (a LocalCluster here, or
`--scheduler ADDRESS`: start its workers with OMP_WAIT_POLICY=passive); each result is written
to DIR/sweep.csv and DIR/sweep.json as it arrives, so an interrupted sweep keeps what it has,
and points already there with status "ok" are not run again.

Cost is the time spent stepping (run_dam_break's wall_s) after a warm-up run of the same
compile-time choices in the same worker: numba compiles each specialization once per process
(10-18 s here), which would otherwise be charged to whichever point came first. The process's
CPU time (cpu_s) and the machine's load average (load_1min) are recorded beside it: on a
shared machine they say how far wall_s can be trusted.
"""
import contextlib
import csv
import io
import json
import logging
import math
import os
import signal
import socket
import threading
import time
from pathlib import Path

from sphcore.errors import Interrupted, SweepError
from sphcore.output import atomic_savefig, atomic_write_bytes
from sphcore.validate.configs import CONFIGS, RECOMMENDED_CONFIG
from sphcore.validate.dam_break import SETTINGS
from sphcore.validate.files import check, read_json, unreadable

AXES = ("backend", "resolution", "dt_fraction", "precision", "equation_of_state", "stiffness",
        "neighbour_search", "alpha", "config")
POINT_KEYS = AXES + ("t_end",)
DEFAULT = {k: SETTINGS[k] for k in POINT_KEYS}
THRESHOLD = 0.15  # RMS of Z against Martin & Moyce's Table 2 that a setting must meet (issue 5)
ERROR = "rms_Z_table2"
COST = "wall_s"
SERIES = ("table2", "fig3_a2.25", "fig3_a1.125", "koshizuka")
RESULT_COLUMNS = (["status", "error", "dtype", "device", "host", "particles", "steps", "dt", "wall_s", "steps_per_s",
                   "particle_steps_per_s", "warmup_s", "cpu_s", "load_1min", "rms_Z_table2", "rms_Z_table2_unshifted",
                   "best_shift_T_table2", "points_table2"] + [f"rms_Z_{s}" for s in SERIES[1:]])
COLUMNS = ["point", "varied", *POINT_KEYS, *RESULT_COLUMNS]
QUICK_T_END = 0.1  # s: T = 0.9, the first three points of Table 2


def at(**changes):
    """The default point with `changes`."""
    return {**DEFAULT, **changes}


def design(quick=False, backends=("numba",), vulkan_on_cpu=True):
    """The points of the sweep, cheapest first within each block.

    Default (numba, 29 points): resolution 10..56 at the defaults and with 4x the viscosity;
    10..40 with Tait and with half the time step; at the default resolution (40) the time step
    at 1/4, 2x and 4x the bound, float64, 16x the viscosity, the stiffness at 1/4 and 4x (both
    laws); all-pairs neighbours at 16 and 25 only (O(N^2): 300 s at 40). Vulkan gets the same
    design on a GPU; on a CPU device (lavapipe, 1-3x slower than numba here) five small points.
    `quick`: resolutions 8 and 10 for 0.1 s, one point per axis (for tests and CI).
    """
    if quick:
        quick_at = lambda **change: at(**{"t_end": QUICK_T_END, "resolution": 8, **change})  # noqa: E731
        points = [quick_at(resolution=10), quick_at()]
        points += [quick_at(**change) for change in (
            {"equation_of_state": "tait"}, {"dt_fraction": 0.5}, {"stiffness": 400.0}, {"alpha": 0.05},
            {"precision": "float64"}, {"neighbour_search": "all_pairs"}, {"config": RECOMMENDED_CONFIG})]
        small = [quick_at(backend="vulkan"), quick_at(backend="vulkan", precision="float64")]
        return [p for p in points if "numba" in backends] + (small if "vulkan" in backends else [])
    ladder = (10, 16, 25, 40, 56)
    viscous = 4 * DEFAULT["alpha"]
    points = [at(resolution=r) for r in ladder]
    for r in ladder:  # the ladder crossed with the equation of state, the time step and the viscosity
        points += [at(resolution=r, equation_of_state="tait"), at(resolution=r, dt_fraction=0.5)] if r < 56 else []
        points += [at(resolution=r, alpha=viscous)]
    points += [at(dt_fraction=f) for f in (0.25, 2.0, 4.0)] + [at(precision="float64"), at(alpha=4 * viscous)]
    points += [at(equation_of_state=eos, stiffness=k) for eos in ("linear", "tait") for k in (225.0, 3600.0)]
    points += [at(resolution=r, neighbour_search="all_pairs") for r in (16, 25)]
    # the model (issue 12): every named configuration at the default resolution, the recommended
    # one along the resolution ladder
    points += [at(config=name) for name in CONFIGS if name != DEFAULT["config"]]
    points += [at(resolution=r, config=RECOMMENDED_CONFIG) for r in ladder if r != DEFAULT["resolution"]]
    # issue 14: DFSPH beside the state equation at 16 and 25 too (at 40: its configuration above)
    points += [at(resolution=r, config="dfsph") for r in (16, 25)]
    out = [p for p in points if "numba" in backends]
    if "vulkan" in backends:
        small = [at(resolution=r) for r in (10, 16, 25)] + [
            at(resolution=16, precision="float64"), at(resolution=16, equation_of_state="tait")]
        out += [{**p, "backend": "vulkan"} for p in (small if vulkan_on_cpu else points)]
    return out


def varied(point):
    """The axes in which `point` differs from DEFAULT, joined by '+' ("default" if none)."""
    names = [k for k in POINT_KEYS if point[k] != DEFAULT[k]]
    return "+".join(names) or "default"


def label(row):
    """A short name of a point: its values that differ from DEFAULT."""
    short = {"resolution": "res", "dt_fraction": "dt x", "equation_of_state": "", "stiffness": "k",
             "neighbour_search": "", "precision": "", "backend": "", "alpha": "alpha", "t_end": "t_end", "config": ""}
    row = {**DEFAULT, **row}  # a table written before an axis existed has its default
    parts = [f"{short[k]} {row[k]:g}".strip() if isinstance(row[k], (int, float)) else str(row[k])
             for k in POINT_KEYS if row[k] != DEFAULT[k]]
    return ", ".join(parts) or "default"


# ---- in the worker ----

_WARM = {}  # (backend, precision, eos, search) -> dtype, device, warm-up seconds, in this process


def warm_up(point):
    """Compile this point's stages in this process outside the timing (a few steps of a small
    column); the dtype of the particle buffers the backend actually holds and its device."""
    from sphcore.simulation import Simulation
    from sphcore.validate.dam_break import dam_break_scene

    key = (point["backend"], point["precision"], point["equation_of_state"], point["neighbour_search"], point["config"])
    if key not in _WARM:
        start = time.perf_counter()
        sim = Simulation(dam_break_scene({**point, "resolution": 6}), point["backend"])
        try:
            sim.advance(2)
            dtype = str(sim.read()["particle_x"].dtype)
            device = sim.device_name
            if device == "cpu":
                import numba
                device = f"cpu, numba {numba.get_num_threads()} threads"
        finally:
            sim.close()
        _WARM[key] = {"dtype": dtype, "device": device, "warmup_s": time.perf_counter() - start}
    return _WARM[key]


def first_line(error):
    text = str(error).strip().splitlines()
    return f"{type(error).__name__}: {text[0] if text else ''}".rstrip(": ")


def run_point(point):
    """One row of the table for `point`; an exception becomes status "failed" with its type and
    first line (the other points go on)."""
    from sphcore.validate.dam_break import run_dam_break

    row = {**point, "host": socket.gethostname()}
    try:
        row.update(warm_up(point))
        cpu = time.process_time()
        _, s = run_dam_break(point, progress=False)
        cpu = time.process_time() - cpu
    except Exception as e:  # noqa: BLE001 - recorded, not raised: one bad point must not stop the sweep
        return {**row, "status": "failed", "error": first_line(e), "load_1min": os.getloadavg()[0]}
    wall = s["wall_s"]
    row.update({k: s[k] for k in RESULT_COLUMNS if k in s})
    row.update(cpu_s=cpu, load_1min=os.getloadavg()[0])
    row.update(status="ok", error="", steps_per_s=s["steps"] / wall if wall > 0 else math.nan,
               particle_steps_per_s=s["steps"] * s["particles"] / wall if wall > 0 else math.nan)
    return row


# ---- the table ----

def point_key(row):
    return json.dumps({k: row.get(k, DEFAULT[k]) for k in POINT_KEYS}, sort_keys=True)


def finite(value):
    return isinstance(value, (int, float)) and math.isfinite(value)


def clean(value):
    """`value` with NaN and infinities as None: JSON has no NaN."""
    if isinstance(value, dict):
        return {k: clean(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [clean(v) for v in value]
    return None if isinstance(value, float) and not math.isfinite(value) else value


def ok_rows(rows):
    """Rows that ran and have a finite error and cost."""
    return [r for r in rows if r.get("status") == "ok" and finite(r.get(ERROR)) and finite(r.get(COST))]


def write_table(out, rows, meta):
    """DIR/sweep.csv and DIR/sweep.json, each replaced atomically."""
    rows = sorted(rows, key=lambda r: r["point"])
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=COLUMNS, lineterminator="\n", extrasaction="ignore")
    writer.writeheader()
    for r in rows:
        writer.writerow({k: (f"{v:.6g}" if isinstance(v, float) and math.isfinite(v) else
                             "" if isinstance(v, float) else v) for k, v in r.items()})
    atomic_write_bytes(Path(out) / "sweep.csv", buf.getvalue().encode())
    atomic_write_bytes(Path(out) / "sweep.json", json.dumps(clean({"sweep": meta, "rows": rows}), indent=1).encode())


POINT_NUMBERS = ("resolution", "dt_fraction", "stiffness", "alpha", "t_end")
ROW_TEXTS = ("status", "error", "dtype", "device", "host")  # the other result columns are numbers


def read_table(out):
    """(rows, meta) of DIR/sweep.json, ([], {}) where there is none; ResultsError naming the file
    and what is wrong with it where it is not a sweep table (it is left as it is)."""
    path = Path(out) / "sweep.json"
    if not path.exists():
        return [], {}
    data = check(path, read_json(path), required=("rows", "sweep"), lists=("rows",), dicts=("sweep",))
    for i, r in enumerate(data["rows"]):  # the values the design compares and sorts
        if not isinstance(r, dict):
            raise unreadable(path, f"row {i} is not an object")
        check(f"{path}, row {i}", r, numbers=POINT_NUMBERS + tuple(k for k in RESULT_COLUMNS if k not in ROW_TEXTS),
              texts=ROW_TEXTS + tuple(k for k in POINT_KEYS if k not in POINT_NUMBERS))
    rows = [{**DEFAULT, **{k: (math.nan if v is None else v) for k, v in r.items()}} for r in data["rows"]]
    return rows, data["sweep"]


# ---- the Pareto front and the recommendations ----

def pareto_front(rows):
    """The rows no other row beats in both error and cost (at least as good in both, better in
    one), cheapest first."""
    rows = ok_rows(rows)
    front = [p for p in rows if not any(q[COST] <= p[COST] and q[ERROR] <= p[ERROR]
                                        and (q[COST] < p[COST] or q[ERROR] < p[ERROR]) for q in rows)]
    return sorted(front, key=lambda r: (r[COST], r[ERROR]))


def effects(rows, axis):
    """What changing `axis` alone did: for each set of values of the other axes (its `context`,
    given as the values that differ from DEFAULT) with two or more values of `axis`, the
    points in order of `axis`. The context {} is the one-at-a-time variation around the default."""
    groups = {}
    for r in rows:
        context = {k: r[k] for k in POINT_KEYS if k != axis and r[k] != DEFAULT[k]}
        groups.setdefault(json.dumps(context, sort_keys=True), (context, []))[1].append(r)
    out = []
    for context, members in groups.values():
        if len({r[axis] for r in members}) < 2:
            continue
        values = [{axis: r[axis], "status": r["status"], ERROR: r.get(ERROR), COST: r.get(COST),
                   "best_shift_T_table2": r.get("best_shift_T_table2"), "error": r.get("error", "")}
                  for r in sorted(members, key=lambda r: (str(type(r[axis])), r[axis]))]
        ok = [v[ERROR] for v in values if v["status"] == "ok" and finite(v[ERROR])]
        out.append({"context": context, "values": values,
                    "rms_spread": max(ok) - min(ok) if len(ok) > 1 else None})
    return sorted(out, key=lambda e: (len(e["context"]), json.dumps(e["context"], sort_keys=True)))


def recommendations(rows, threshold=THRESHOLD):
    """The cheapest point with RMS <= threshold, the most accurate, the Pareto front, the failed
    points, and per axis what changing it did; with a text that says it in words."""
    ok = ok_rows(rows)
    meeting = [r for r in ok if r[ERROR] <= threshold]

    def pick(r):
        return None if r is None else {"point": r["point"], "label": label(r), ERROR: r[ERROR], COST: r[COST],
                                       **{k: r[k] for k in POINT_KEYS}}

    rec = {"threshold": threshold, "error": ERROR, "cost": COST, "points": len(rows), "ok": len(ok),
           "cheapest_meeting_threshold": pick(min(meeting, key=lambda r: (r[COST], r[ERROR]), default=None)),
           "most_accurate": pick(min(ok, key=lambda r: (r[ERROR], r[COST]), default=None)),
           "pareto_front": [pick(r) for r in pareto_front(rows)],
           "failed": [{"point": r["point"], "label": label(r), "error": r.get("error", "")}
                      for r in rows if r.get("status") != "ok"],
           "effects": {axis: effects(rows, axis) for axis in AXES},
           "configurations": by_configuration(rows, threshold, pick)}
    rec["text"] = describe(rec)
    return rec


def by_configuration(rows, threshold, pick):
    """Per named configuration (the model, issue 12): its points, the most accurate, the cheapest
    with RMS <= threshold, and its points on the Pareto front."""
    front = {r["point"] for r in pareto_front(rows)}
    out = []
    for name in dict.fromkeys(r.get("config", DEFAULT["config"]) for r in rows):
        mine = [r for r in rows if r.get("config", DEFAULT["config"]) == name]
        ok = ok_rows(mine)
        meeting = [r for r in ok if r[ERROR] <= threshold]
        out.append({"config": name, "points": len(mine), "ok": len(ok),
                    "most_accurate": pick(min(ok, key=lambda r: (r[ERROR], r[COST]), default=None)),
                    "cheapest_meeting_threshold": pick(min(meeting, key=lambda r: (r[COST], r[ERROR]), default=None)),
                    "on_pareto_front": [r["point"] for r in ok if r["point"] in front],
                    "failed": sorted({r.get("error", "") for r in mine if r.get("status") != "ok"})})
    return out


def _value(v):
    return f"{v:g}" if isinstance(v, (int, float)) else str(v)


def describe(rec):
    """Lines of text for `rec`, every number from the table."""
    lines = []
    best, cheap = rec["most_accurate"], rec["cheapest_meeting_threshold"]
    lines.append(f"{rec['ok']} of {rec['points']} points ran; error = RMS of Z against Martin & Moyce Table 2 "
                 f"(simulated T + gate shift); cost = seconds stepping.")
    if cheap:
        lines.append(f"Cheapest with RMS <= {rec['threshold']:g}: {cheap['label']} "
                     f"(RMS {cheap[ERROR]:.3f}, {cheap[COST]:.2f} s).")
    else:
        lines.append(f"No point reached RMS <= {rec['threshold']:g}.")
    if best:
        lines.append(f"Most accurate: {best['label']} (RMS {best[ERROR]:.3f}, {best[COST]:.2f} s).")
    lines.append("Pareto front (cheapest first): " + "; ".join(
        f"{p['label']} ({p[ERROR]:.3f}, {p[COST]:.2f} s)" for p in rec["pareto_front"]) + ".")
    for axis, groups in rec["effects"].items():
        for g in groups:
            where = ", ".join(f"{k} {_value(v)}" for k, v in g["context"].items()) or "around the default"
            steps = [f"{_value(v[axis])}: " + (f"{v[ERROR]:.3f} in {v[COST]:.2f} s" if v["status"] == "ok"
                                                  else f"failed ({v['error'].split(':')[0]})") for v in g["values"]]
            lines.append(f"{axis} ({where}): " + "; ".join(steps) + ".")
    for c in rec.get("configurations", []):
        best, cheap = c["most_accurate"], c["cheapest_meeting_threshold"]
        text = (f"Configuration {c['config']}: {c['ok']} of {c['points']} points ran"
                + (f"; most accurate {best['label']} (RMS {best[ERROR]:.3f}, {best[COST]:.2f} s)" if best else "")
                + (f"; cheapest with RMS <= {rec['threshold']:g} {cheap['label']} ({cheap[ERROR]:.3f}, "
                   f"{cheap[COST]:.2f} s)" if cheap else "")
                + f"; {len(c['on_pareto_front'])} on the Pareto front"
                + (f"; failed: {'; '.join(c['failed'])}" if c["failed"] else "") + ".")
        lines.append(text)
    lines += limits(rec["effects"])
    if rec["failed"]:
        lines.append(f"Failed ({len(rec['failed'])}): "
                     + "; ".join(f"{f['label']}: {f['error']}" for f in rec["failed"]) + ".")
    return lines


ROUND_OFF_AXES = ("precision", "neighbour_search", "backend")  # the same equations, other round-off


def limits(effects):
    """Lines on what limits the accuracy, from `effects`: the change of the RMS that round-off
    alone makes (axes that change no equation), the axes that change it by more around the
    default, and whether a finer resolution still reduced it."""
    noise = [abs(a[ERROR] - b[ERROR]) for axis in ROUND_OFF_AXES for g in effects[axis]
             for a in g["values"] for b in g["values"] if a["status"] == b["status"] == "ok"]
    noise = max(noise, default=None)
    spreads = {axis: g["rms_spread"] for axis in AXES for g in effects[axis]
               if not g["context"] and g["rms_spread"] is not None}
    lines = []
    if spreads:
        lines.append("Change of the RMS across each axis around the default, largest first: " + ", ".join(
            f"{axis} {spreads[axis]:.3f}" for axis in sorted(spreads, key=spreads.get, reverse=True)) + ".")
    if noise is None:
        return lines
    lines.append(f"Round-off alone (the same equations in float32 and float64, grid and all-pairs "
                 f"neighbours, numba and Vulkan) moved the RMS by up to {noise:.3f}: smaller changes are not significant.")
    small = [a for a in spreads if spreads[a] <= noise and a not in ROUND_OFF_AXES]
    large = [a for a in spreads if spreads[a] > noise and a not in ROUND_OFF_AXES]
    if small:
        lines.append(f"Not significant around the default: {', '.join(small)}.")
    if large:
        lines.append(f"Significant around the default: {', '.join(large)}.")
    for g in effects["resolution"]:
        ok = [v for v in g["values"] if v["status"] == "ok" and finite(v[ERROR])]
        if len(ok) < 3:
            continue
        best = min(ok, key=lambda v: v[ERROR])
        finer = [v for v in ok if v["resolution"] > best["resolution"]]
        where = ", ".join(f"{k} {_value(v)}" for k, v in g["context"].items()) or "the defaults"
        shifts = ", ".join(f"{v['best_shift_T_table2']:g}" for v in ok if finite(v["best_shift_T_table2"]))
        if finer and max(v[ERROR] for v in finer) - best[ERROR] > noise:
            lines.append(f"Resolution at {where}: the RMS is smallest at {best['resolution']} ({best[ERROR]:.3f}); "
                         f"finer is worse (" + ", ".join(f"{v['resolution']}: {v[ERROR]:.3f}" for v in finer) +
                         f"), so resolution does not limit it there; the best time shift against Table 2 by "
                         f"resolution: {shifts}.")
        elif not finer:
            lines.append(f"Resolution at {where}: the RMS is smallest at the finest resolution, {best['resolution']} "
                         f"({best[ERROR]:.3f}).")
        else:
            lines.append(f"Resolution at {where}: from {best['resolution']} on the RMS stays within {noise:.3f} "
                         f"({', '.join(f'{v[ERROR]:.3f}' for v in [best, *finer])}): converged to the round-off's "
                         f"significance; the best time shift by resolution: {shifts}.")
    return lines


MARKERS = "osD^vP<>X*hpd8H"


def others(row):
    """What `row` varies beside its configuration ("default" if nothing): the marker's group."""
    return "+".join(k for k in varied(row).split("+") if k != "config") or "default"


def plot_pareto(rows, path, threshold=THRESHOLD):
    """Error against cost (log): colour by configuration, marker by what else was varied (the
    resolution ladder, the time step, ..., the backend among them), each with its legend; the
    front drawn and its points labelled."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    ok = ok_rows(rows)
    fig, ax = plt.subplots(figsize=(12, 6.6), dpi=110)
    configs = list(dict.fromkeys([c for c in CONFIGS if any(r["config"] == c for r in ok)]
                                 + [r["config"] for r in ok]))  # configs.py's order, then any other name
    # tab20's dark shades first, then its light ones: neighbours in the legend differ in hue
    colours = dict(zip(configs, plt.get_cmap("tab20")([2 * i % 20 + 2 * i // 20 for i in range(len(configs))])))
    groups = sorted({others(r) for r in ok}, key=lambda g: (g != "default", g))
    markers = {g: MARKERS[i % len(MARKERS)] for i, g in enumerate(groups)}
    for r in ok:
        ax.scatter(r[COST], r[ERROR], color=colours[r["config"]], marker=markers[others(r)], s=40,
                   edgecolor="k", linewidth=0.4)
    front = pareto_front(rows)
    if front:
        ax.step([r[COST] for r in front], [r[ERROR] for r in front], "k-", where="post", lw=1.2,
                label="Pareto front", zorder=0)
        for k, r in enumerate(front, 1):
            ax.annotate(str(k), (r[COST], r[ERROR]), textcoords="offset points", xytext=(-3, -12), fontsize=8,
                        weight="bold")
        ax.text(1.02, 0.0, "Pareto front:\n" + "\n".join(
            f"{k}  {label(r)}: {r[ERROR]:.3f}, {r[COST]:.3g} s" for k, r in enumerate(front, 1)),
                transform=ax.transAxes, va="bottom", fontsize=7, family="monospace")
    ax.axhline(threshold, color="r", ls="--", lw=0.8, label=f"RMS = {threshold:g}")
    failed = len(rows) - len(ok)
    ax.set(xscale="log", xlabel="cost: wall time stepping [s] (log)", ylabel="error: RMS of Z against Table 2",
           title=f"2D dam break: error against cost, {len(ok)} points"
                 + (f" ({failed} failed, not shown)" if failed else ""))
    ax.grid(True, which="both", lw=0.3, alpha=0.5)
    dot = lambda **kw: Line2D([], [], ls="", markersize=6, markeredgecolor="k", markeredgewidth=0.4, **kw)  # noqa: E731
    fig.legend([dot(marker="o", color=colours[c]) for c in configs], configs, title="configuration (colour)",
               fontsize=7, title_fontsize=7, loc="upper left", bbox_to_anchor=(0.6, 0.93))
    handles, names = ax.get_legend_handles_labels()  # the front and the threshold
    fig.legend([dot(marker=markers[g], color="0.8") for g in groups] + handles, groups + names,
               title="varied beside it (marker)", fontsize=7, title_fontsize=7, loc="upper left",
               bbox_to_anchor=(0.77, 0.93))
    fig.subplots_adjust(left=0.07, right=0.58, bottom=0.09, top=0.93)
    atomic_savefig(fig, path)
    plt.close(fig)
    return path


def write_outputs(out, rows):
    """pareto.png, recommendations.json and recommendations.txt from the table."""
    out = Path(out)
    plot_pareto(rows, out / "pareto.png")
    rec = recommendations(rows)
    atomic_write_bytes(out / "recommendations.json", json.dumps(clean(rec), indent=1).encode())
    atomic_write_bytes(out / "recommendations.txt", ("\n".join(rec["text"]) + "\n").encode())
    return rec


# ---- execution ----

@contextlib.contextmanager
def sigint_ignored():
    """SIGINT ignored for the block (main thread; elsewhere nothing changes). Ctrl-C at a terminal
    reaches every process of its group: the Dask workers started in this block inherit the
    disposition, so only this process hears it and closes the cluster (no worker tracebacks); and
    closing, or writing the last tables, is not cut short by a second Ctrl-C."""
    main = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN) if main else None
    try:
        yield
    finally:
        if main:
            signal.signal(signal.SIGINT, signal.SIG_DFL if previous is None else previous)


def local_cluster(workers):
    """A LocalCluster of `workers` processes, one task each, the cores shared out as numba threads
    (measured on 2 cores: one worker with 2 threads steps as many points per second as two with
    one, and compiles each specialization once instead of twice)."""
    from distributed import LocalCluster

    threads = str(max(1, (os.cpu_count() or 1) // workers))
    env = {"NUMBA_NUM_THREADS": threads, "OMP_NUM_THREADS": threads, "OMP_WAIT_POLICY": "passive"}
    # silence_logs: not the nanny's warnings when it stops a worker, nor a worker's error (with a traceback) when
    # the scheduler closed before its last heartbeat, as after a Ctrl-C (a point's own error reaches its future)
    return LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None, env=env,
                        silence_logs=logging.CRITICAL)


def connect(scheduler, workers, timeout=10):
    """(client, cluster or None): a client of the scheduler at `scheduler`, else of a new LocalCluster."""
    from distributed import Client

    if scheduler is None:
        with sigint_ignored():  # the workers ignore Ctrl-C; a Ctrl-C while they start is lost
            cluster = local_cluster(workers or 1)
            return Client(cluster), cluster
    try:
        return Client(scheduler, timeout=timeout), None
    except (OSError, ValueError, TypeError) as e:
        raise SweepError(f"--scheduler {scheduler}: cannot reach a Dask scheduler there ({first_line(e)}); "
                         "start one with `dask scheduler` (and `dask worker ADDRESS` on each machine) "
                         "or leave --scheduler out for a local cluster") from None


def vulkan_is_cpu(client):
    """Whether the Vulkan device a worker picks is a CPU (lavapipe), or there is none."""
    def probe():
        from sphcore.vk_runner import Context, VulkanError
        try:
            with Context() as ctx:
                return ctx.device_type == "CPU"
        except VulkanError:
            return True
    return client.submit(probe, pure=False).result()


def run_sweep(out, points=None, scheduler=None, workers=None, quick=False, backends=("numba",), progress=True,
              timeout=10):
    """Run the points (default: `design(quick, backends)`) through Dask into DIR; return the rows.

    Points already in DIR/sweep.json with status "ok" are kept and not run again (rows there
    that this design does not have are kept too, numbered after it); every result is written
    as it arrives; pareto.png and recommendations.* are written at the end, or when the sweep
    is interrupted, from what there is. Ctrl-C stops the cluster quietly and raises Interrupted
    saying how many points are done; the same call runs the rest."""
    if scheduler is not None and workers is not None:
        raise SweepError("--workers sizes the local cluster; with --scheduler the scheduler's workers run the points")
    # a Ctrl-C stops the local workers with a semaphore unreleased, which multiprocessing's resource tracker (a process
    # started later, with this environment) cleans up at the end with a warning under the one line: filtered there
    quiet, filters = "ignore:resource_tracker:UserWarning", os.environ.get("PYTHONWARNINGS", "")
    if quiet not in filters.split(","):  # (once: a process may run several sweeps)
        os.environ["PYTHONWARNINGS"] = ",".join(w for w in (filters, quiet) if w)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    previous, earlier = read_table(out)
    meta = {"started": time.strftime("%Y-%m-%d %H:%M:%S %z"), "scheduler": scheduler or "LocalCluster",
            "client_host": socket.gethostname(), "cpu_count": os.cpu_count(), "quick": quick,
            "backends": list(backends), "threshold": THRESHOLD}
    if earlier:  # how the rows kept from an earlier sweep into DIR ran
        meta["earlier_runs"] = earlier.pop("earlier_runs", []) + [earlier]
    client = cluster = None
    rows, total = {}, None
    try:
        if points is None:
            on_cpu = True
            if "vulkan" in backends:
                client, cluster = connect(scheduler, workers, timeout)
                on_cpu = vulkan_is_cpu(client)
            points = design(quick, backends, vulkan_on_cpu=on_cpu)
        points = [{**DEFAULT, **p} for p in points]
        keys = [point_key(p) for p in points]
        done = {point_key(r): r for r in previous if r.get("status") == "ok"}
        rows = {i: {**done[k], "point": i, "varied": varied(p)} for i, (k, p) in enumerate(zip(keys, points)) if k in done}
        extra = [r for r in previous if point_key(r) not in set(keys)]
        rows.update({len(points) + j: {**r, "point": len(points) + j} for j, r in enumerate(extra)})
        todo = [(i, p) for i, p in enumerate(points) if i not in rows]
        meta["points"] = total = len(points)
        meta["reused"] = len(points) - len(todo)
        if todo and client is None:
            client, cluster = connect(scheduler, workers, timeout)
        if client is not None:
            meta["workers"] = len(client.scheduler_info()["workers"])
        run_points(client, todo, rows, out, meta, progress)
    except KeyboardInterrupt:
        ok = sum(r.get("status") == "ok" for i, r in rows.items() if total is None or i < total)
        done = f"{ok} of {total} points done" if total else "before the points were made"
        kept = f", written to {out}/sweep.csv and sweep.json" if rows else ""
        raise Interrupted(signal.SIGINT, f"interrupted; {done}{kept} (the same command runs the rest)") from None
    finally:
        with sigint_ignored():
            if client is not None:
                client.close()
            if cluster is not None:
                cluster.close()
    return sorted(rows.values(), key=lambda r: r["point"])


def run_points(client, todo, rows, out, meta, progress):
    """Submit `todo` [(index, point)], put each result into `rows` and the table as it arrives."""
    from distributed import as_completed
    from tqdm import tqdm

    started = time.perf_counter()
    try:
        futures = {client.submit(run_point, p, pure=False): (i, p) for i, p in todo}
        bar = tqdm(as_completed(futures) if futures else [], total=len(futures), unit="point", desc="sweep",
                   disable=not progress)
        for future in bar:
            i, p = futures[future]
            try:
                row = future.result()
            except Exception as e:  # noqa: BLE001 - a worker that died: KilledWorker, lost connection
                row = {**p, "status": "failed", "error": first_line(e)}
            rows[i] = {**row, "point": i, "varied": varied(p)}
            if row["status"] != "ok":
                bar.write(f"point {i} ({label(p)}) failed: {row['error']}")
            meta["elapsed_s"] = time.perf_counter() - started
            write_table(out, rows.values(), meta)
    finally:
        meta["finished"] = time.strftime("%Y-%m-%d %H:%M:%S %z")
        meta["elapsed_s"] = time.perf_counter() - started
        if rows:
            with sigint_ignored():
                write_table(out, rows.values(), meta)
                write_outputs(out, list(rows.values()))
