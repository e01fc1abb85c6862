"""`sphcore report --out DIR`: one HTML page of the validation results, generated, never edited
by hand.

It reads what the other commands wrote (from the `--results` folders in order, then DIR): the
2D dam break (run into DIR at the default settings where no folder has dam_break_2d.json), the
sweep (sweep.json or sweep.csv, pareto.png, recommendations.json), and any files named after
the other sections' prefixes (the 3D dam break, SPHERIC test 2, the stability matrix): a JSON
list of dicts or a CSV becomes a table, a JSON dict a table of its keys, a PNG a picture. A
part not found says "not run" and names the command that makes it. Then the versions and the
hardware. Pictures are copied next to index.html, so the folder is the whole report.
"""
import html
import json
import math
import os
import platform
import shutil
import subprocess
import sys
import time
from importlib import metadata
from pathlib import Path

from sphcore.output import atomic_write_bytes
from sphcore.validate.files import ResultsError, check, check_png, read_csv, read_json, unreadable

REPO = Path(__file__).resolve().parent.parent.parent
# prefix -> (title, the command that writes its files); read generically
OTHER_SECTIONS = {
    "dam_break_3d": ("3D dam break", "sphcore validate dam-break --dimension 3 --out {dir}"),
    "spheric_test2": ("SPHERIC benchmark test 2: water heights H1–H4", "sphcore validate spheric --out {dir}"),
    "stability": ("Stability at the extremes", "sphcore validate stability --out {dir}"),
}
PACKAGES = ("numpy", "numba", "vulkan", "matplotlib", "dask", "distributed", "tqdm")
SUMMARY_NUMBERS = ("rms_Z_table2", "rms_Z_table2_unshifted", "gate_shift_T", "best_shift_T_table2", "particles",
                   "steps", "dt", "wall_s")  # of dam_break_2d.json, where present
PLOT_COLUMNS = ("T", "Z", "tau", "H")  # of dam_break_2d.csv, for its picture
SWEEP_COLUMNS = ("point", "varied", "backend", "resolution", "dt_fraction", "precision", "equation_of_state", "stiffness",
                 "neighbour_search", "alpha", "config", "t_end", "status", "dtype", "device", "particles", "steps", "dt", "wall_s",
                 "steps_per_s", "rms_Z_table2", "rms_Z_table2_unshifted", "best_shift_T_table2", "error")
STYLE = """body{font-family:sans-serif;max-width:1200px;margin:2em auto;padding:0 1em;color:#222}
table{border-collapse:collapse;font-size:13px;margin:.5em 0}td,th{border:1px solid #ccc;padding:2px 6px;text-align:right}
th{background:#eee}td.s{text-align:left}img{max-width:100%}.missing{color:#a00}pre{white-space:pre-wrap;font-size:13px}
details{margin:.5em 0}code{background:#f4f4f4;padding:0 3px}"""


# ---- HTML pieces ----

def esc(value):
    return html.escape(str(value))


def cell(value):
    """A table cell: floats to 4 significant digits, missing values as a dash, text left-aligned."""
    if value is None or isinstance(value, float) and math.isnan(value):
        return "<td>–</td>"
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return f'<td class="s">{esc(value)}</td>'
    return f"<td>{value:.4g}</td>" if isinstance(value, float) else f"<td>{value}</td>"


def table(rows, columns=None):
    """A list of dicts as an HTML table, columns in first-seen order unless given."""
    if columns is None:
        columns = list(dict.fromkeys(k for r in rows for k in r))
    head = "".join(f"<th>{esc(c)}</th>" for c in columns)
    body = "\n".join("<tr>" + "".join(cell(r.get(c)) for c in columns) + "</tr>" for r in rows)
    return f"<table><tr>{head}</tr>\n{body}</table>"


def key_values(d):
    """A dict's scalar entries as a two-column table; nested dicts and lists of dicts as their own tables."""
    nested = lambda v: isinstance(v, dict) or isinstance(v, list) and any(isinstance(x, (dict, list)) for x in v)  # noqa: E731
    scalars = {k: ", ".join(map(str, v)) if isinstance(v, list) else v for k, v in d.items() if not nested(v)}
    parts = [table([{"key": k, "value": v} for k, v in scalars.items()], ["key", "value"])] if scalars else []
    for k, v in d.items():
        if isinstance(v, dict):
            parts.append(f"<h4>{esc(k)}</h4>" + key_values(v))
        elif nested(v) and all(isinstance(x, dict) for x in v):
            parts.append(f"<h4>{esc(k)}</h4>" + table(v))
        elif nested(v):
            parts.append(f"<h4>{esc(k)}</h4><pre>{esc(json.dumps(v))}</pre>")
    return "\n".join(parts)


def render_json(value):
    if isinstance(value, list) and all(isinstance(x, dict) for x in value):
        return table(value)
    if isinstance(value, dict):
        return key_values(value)
    return f"<pre>{esc(json.dumps(value, indent=1))}</pre>"


def shown(path):
    """`path` relative to the current folder where it lies below it (a report made in a checkout
    names validation/results, not the checkout's absolute path)."""
    relative = os.path.relpath(path)
    return str(path) if relative.startswith("..") else relative


def details(summary, body, open_=False):
    return f"<details{' open' if open_ else ''}><summary>{summary}</summary>\n{body}\n</details>"


class Page:
    """Sections of the page, and the pictures copied next to it."""

    def __init__(self, out, dirs):
        self.out, self.dirs, self.parts = out, dirs, []
        self.skipped = []  # (path, why) of JSON files found by summaries() that could not be read

    def find(self, name):
        return next((d / name for d in self.dirs if (d / name).is_file()), None)

    def matching(self, prefix, suffixes=(".json", ".csv", ".png")):
        names = {p.name for d in self.dirs if d.is_dir() for p in d.glob(f"{prefix}*")
                 if p.suffix in suffixes and p.is_file()}  # not a folder or a dangling link of that name
        return [self.find(n) for n in sorted(names)]

    def image(self, path, alt=""):
        """An <img> of `path` (checked to be a whole PNG), copied next to index.html when it lies elsewhere."""
        check_png(path)
        target = self.out / path.name
        if path.resolve() != target.resolve():
            shutil.copyfile(path, target)
        return f'<p><img src="{esc(path.name)}" alt="{esc(alt or path.name)}"></p>'

    def link(self, path):
        return f'<code>{esc(shown(path))}</code>'

    def add(self, anchor, title, body):
        self.parts.append((anchor, title, body))

    def missing(self, command):
        return f'<p class="missing">not run: <code>{esc(command.format(dir=shown(self.dirs[0])))}</code> writes it</p>'

    def files(self, prefix):
        """Every JSON, CSV and PNG named `prefix*`, grouped by name: the picture, the JSON as tables,
        the CSV as a table (only linked where a JSON of the same name says it already)."""
        out = []
        paths = self.matching(prefix)
        order = {".png": 0, ".json": 1, ".csv": 2}
        for stem in sorted({p.stem for p in paths}):
            group = sorted((p for p in paths if p.stem == stem), key=lambda p: order[p.suffix])
            out.append(f"<h3>{esc(stem)}</h3>")
            for p in group:
                if p.suffix == ".png":
                    out.append(self.image(p))
                elif p.suffix == ".json":
                    out.append(f"<p>From {self.link(p)}:</p>" + render_json(read_json(p, None)))
                elif any(q.suffix == ".json" for q in group):
                    out.append(f"<p>The series as CSV: {self.link(p)}</p>")
                else:
                    rows = read_csv(p)
                    out.append(details(f"{esc(p.name)}: {len(rows)} rows", table(rows)))
        return out

    def html(self, title, head):
        toc = "".join(f'<li><a href="#{a}">{esc(t)}</a></li>' for a, t, _ in self.parts)
        body = "\n".join(f'<h2 id="{a}">{esc(t)}</h2>\n{b}' for a, t, b in self.parts)
        return (f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8"><title>{esc(title)}</title>'
                f"<style>{STYLE}</style></head>\n<body><h1>{esc(title)}</h1>\n{head}\n<ul>{toc}</ul>\n{body}\n</body></html>\n")


# ---- sections ----

def dam_break_2d(page, settings=None):
    """The 2D dam break at the default settings: picture, errors, settings; run into DIR if absent."""
    from sphcore.validate import dam_break

    found = page.find("dam_break_2d.json")
    png = page.find("dam_break_2d.png")
    if found is None:
        rows, summary = dam_break.run_dam_break(settings, page.out)
        note = f"<p>Run by this report into {page.link(page.out)} (no dam_break_2d.json was there).</p>"
        csv_path = page.out / "dam_break_2d.csv"
    else:
        summary = check(found, read_json(found), numbers=SUMMARY_NUMBERS, dicts=("settings",))
        csv_path = found.with_suffix(".csv")
        rows = read_csv(csv_path, numbers=() if png else PLOT_COLUMNS) if csv_path.is_file() else None
        note = f"<p>Read from {page.link(found)}.</p>"
        if png is None and rows:  # what the picture needs: its title and legend
            check(found, summary, required=("particles", "gate_shift_T", "rms_Z_table2", "settings"))
            check(found, summary["settings"], required=("dimension", "resolution", "equation_of_state", "precision",
                                                        "backend"))
    if png is None and rows:
        png = dam_break.plot(rows, summary, page.out / "dam_break_2d.png")
    errors = [{"series": label, "RMS of Z (T + gate shift)": summary.get(f"rms_Z_{name}"),
               "RMS of Z (unshifted)": summary.get(f"rms_Z_{name}_unshifted"), "points": summary.get(f"points_{name}")}
              for name, (_, label) in dam_break.FRONT_SERIES.items()]
    run = {k: summary.get(k) for k in ("particles", "steps", "dt", "wall_s", "min_neighbours", "gate_shift_T",
                                       "best_shift_T_table2")}
    body = [note, page.image(Path(png), "Z(T) and H(tau)") if png else "<p>no picture (no CSV of the run)</p>",
            "<h3>Errors against the measured fronts</h3>", table(errors),
            f"<p>Gate: {'met' if (summary.get('rms_Z_table2') or math.inf) <= 0.15 else 'not met'} "
            f"(RMS against Table 2 <= 0.15).</p>",
            "<h3>Run</h3>", key_values(run), "<h3>Settings</h3>", key_values(summary.get("settings") or {})]
    if rows:
        body.append(details(f"dam_break_2d.csv: {len(rows)} rows", table(rows)))
    others = [d / "dam_break_2d.json" for d in page.dirs if (d / "dam_break_2d.json").is_file()][1:]
    if others:
        body += ["<h3>Other runs of this case (the other --results folders)</h3>", table([other_run(p) for p in others])]
    page.add("dam_break_2d", "2D dam break after Martin & Moyce (1952)", "\n".join(body))


def other_run(path):
    """A row of the settings and errors of the 2D run summarised in `path`."""
    summary = check(path, read_json(path), dicts=("settings",))
    s = summary.get("settings") or {}
    return {"folder": shown(path.parent), **{k: s.get(k) for k in ("backend", "resolution", "precision",
                                                                   "equation_of_state", "dt_fraction")},
            **{k: summary.get(k) for k in ("device", "particles", "steps", "wall_s", "rms_Z_table2",
                                           "rms_Z_table2_unshifted", "best_shift_T_table2")}}


def sweep_section(page):
    """The sweep: recommendations, the Pareto picture, the table."""
    from sphcore.validate.sweep import label

    source = page.find("sweep.json") or page.find("sweep.csv")
    if source is None:
        page.add("sweep", "Speed and accuracy: the sweep", page.missing("sphcore sweep --out {dir}"))
        return
    meta = {}
    if source.suffix == ".json":
        data = check(source, read_json(source), required=("rows",), lists=("rows",), dicts=("sweep",))
        rows, meta = data["rows"], data.get("sweep") or {}
        if not all(isinstance(r, dict) for r in rows):
            raise unreadable(source, "'rows' is not an array of objects")
    else:
        rows = read_csv(source)
    body = [f"<p>Read from {page.link(source)}: {len(rows)} points, "
            f"{sum(r.get('status') == 'ok' for r in rows)} ok.</p>"]
    rec_path = page.find("recommendations.json")
    if rec_path is not None:
        rec = check(rec_path, read_json(rec_path), dicts=("cheapest_meeting_threshold", "most_accurate"),
                    lists=("text",))
        picks = [{"which": name.replace("_", " "), **rec[name]} for name in ("cheapest_meeting_threshold", "most_accurate")
                 if rec.get(name)]
        body += ["<h3>Recommendations</h3>", table(picks, ["which", "label", "rms_Z_table2", "wall_s", "point"]),
                 "<pre>" + esc("\n".join(map(str, rec.get("text") or []))) + "</pre>"]
    else:
        body.append(page.missing("sphcore sweep --out {dir}").replace("not run", "recommendations.json missing"))
    pareto = page.find("pareto.png")
    body.append(page.image(pareto, "error against cost") if pareto else "<p>no pareto.png</p>")
    labelled = [{"label": label(r) if all(k in r for k in ("backend", "t_end")) else "", **r} for r in rows]
    body.append(details(f"The table ({len(rows)} rows; all columns in {source.name})",
                        table(labelled, ["label"] + [c for c in SWEEP_COLUMNS if any(c in r for r in rows)]), open_=True))
    if meta:
        body += ["<h3>How it ran</h3>", key_values(meta)]
    page.add("sweep", "Speed and accuracy: the sweep", "\n".join(body))


def summaries(page):
    """Every run summary (a JSON dict with "settings") in the results folders and their subfolders,
    each file once: [(path, summary)]. A JSON file that cannot be read, or a summary whose settings are
    not of their kinds, is left out and listed in page.skipped (the page says so)."""
    seen, out = set(), []
    for d in page.dirs:
        if not d.is_dir():
            continue
        for path in sorted(d.rglob("*.json")):
            key = path.resolve()
            if key in seen or len(path.relative_to(d).parts) > 4:
                continue
            seen.add(key)
            try:
                data = read_json(path, None)
                if isinstance(data, dict) and isinstance(data.get("settings"), dict):
                    check(path, data["settings"], numbers=("resolution", "spacing", "dimension", "dt_fraction"),
                          texts=("config", "backend"))
                    out.append((path, check(path, data, texts=("error",))))
            except ResultsError as e:  # any JSON below the folders is scanned: say which were not read
                page.skipped.append((path, e.why))
    return out


MODEL_CASES = {  # case -> (what identifies its summary, its figures: (column, key, scale))
    "Martin & Moyce 1952 (front Z)": ("rms_Z_table2", [("RMS of Z vs Table 2", "rms_Z_table2", 1),
                                                       ("unshifted", "rms_Z_table2_unshifted", 1),
                                                       ("best shift", "best_shift_T_table2", 1)]),
    "Buchner 2002, P1 pressure": ("peak_p_star", [("peak t* error %", "peak_time_error", 100),
                                                 ("peak p* error %", "peak_height_error", 100),
                                                 ("RMS of p*", "rms_p_star", 1),
                                                 ("peak p* error % (running mean)", "peak_height_error_smoothed", 100),
                                                 ("RMS of p* (running mean)", "rms_p_star_smoothed", 1),
                                                 ("RMS of p* vs De Courcy 2024's simulation", "rms_p_star_reference", 1),
                                                 ("the same to t* = 6", "rms_p_star_reference_calm", 1)]),
    "Hydrostatic tank": ("slope_error", [("slope error %", "slope_error", 100),
                                         ("largest deviation % of rho g D", "deviation_max", 100),
                                         ("wall sensors: largest error %", "sensor_error_max", 100)]),
    "SPHERIC test 2": ("rms_H1", [("RMS H1 m", "rms_H1", 1), ("RMS H2 m", "rms_H2", 1), ("RMS H3 m", "rms_H3", 1),
                                  ("RMS H4 m", "rms_H4", 1), ("RMS P1 kPa", "rms_P1", 1e-3)]),
}


def front_convergence(runs):
    """Grid convergence of the Martin & Moyce front: for each configuration and dimension with runs at two
    or more resolutions (each a summary beside its CSV; on either backend, which agree, as tested), the RMS
    of Z(T) between successive resolutions and between each and the finest, over the T all of them cover
    (200 points), and the observed order, log2 of the ratio of successive differences. A solution that
    converges has differences that shrink with resolution, whatever its distance from the experiment."""
    import numpy as np

    groups = {}
    for path, summary in runs:
        s = summary["settings"]
        csv_path = Path(path).with_suffix(".csv")
        if ("rms_Z_table2" in summary and not summary.get("error") and csv_path.is_file()
                and isinstance(s.get("resolution"), (int, float))):
            key = (s.get("config") or "graphics", s.get("dimension") or 2)
            groups.setdefault(key, {})[s.get("resolution")] = (csv_path, s.get("backend"))
    rows = []
    for (config, dim), found in sorted(groups.items()):
        if len(found) < 2:
            continue
        series = {}
        for resolution in sorted(found):
            data = read_csv(found[resolution][0], numbers=("T", "Z"), min_rows=1)
            series[resolution] = (np.array([r["T"] for r in data], float), np.array([r["Z"] for r in data], float))
        T = np.linspace(0.0, min(t[-1] for t, _ in series.values()), 200)
        Z = {res: np.interp(T, t, z) for res, (t, z) in series.items()}
        resolutions = sorted(Z)
        finest = resolutions[-1]
        previous = None
        for coarse, fine in zip(resolutions, resolutions[1:]):
            step = float(np.sqrt(np.mean((Z[coarse] - Z[fine]) ** 2)))
            rows.append({"configuration": config, "dim": dim, "resolutions": f"{coarse} -> {fine}",
                         "backends": f"{found[coarse][1]}, {found[fine][1]}",
                         "RMS of Z between them": step,
                         "finest": finest,
                         "RMS of Z from the finest": float(np.sqrt(np.mean((Z[coarse] - Z[finest]) ** 2))),
                         "observed order": math.log2(previous / step) if previous and step > 0 else None,
                         "T up to": float(T[-1])})
            previous = step
    return rows


def model_section(page):
    """Issue 12: the measured figures of every run found, by case, configuration and resolution:
    today's model ("graphics", the scenes' defaults) beside the recommended one ("engineering")."""
    from sphcore.validate.configs import CONFIGS, DEFAULT_CONFIG, RECOMMENDED_CONFIG, describe

    runs = summaries(page)
    body = [f"<p>Configurations: <b>{esc(describe(DEFAULT_CONFIG))}</b> (today's default); "
            f"<b>{esc(describe(RECOMMENDED_CONFIG))}</b> (recommended). Every run summary found under the results "
            "folders, at any resolution and on any backend; a run that stopped early says so in the last column "
            "(its figures cover the time it ran).</p>"]
    found = False
    for case, (marker, figures) in MODEL_CASES.items():
        rows = []
        for path, summary in runs:
            if marker not in summary:
                continue
            s = summary["settings"]
            config = s.get("config") or DEFAULT_CONFIG
            resolution = s.get("resolution", s.get("spacing"))
            row = {"configuration": config, "dim": s.get("dimension", 3 if "rms_H1" in summary else 2),
                   "resolution": resolution, "backend": s.get("backend"),
                   "device": summary.get("device"), "particles": summary.get("particles"),
                   "dt fraction": s.get("dt_fraction")}
            for column, key, scale in figures:
                value = summary.get(key)
                row[column] = value * scale if isinstance(value, (int, float)) else None
            row["wall s"] = summary.get("wall_s")
            row["stopped"] = (summary.get("error") or "").split(";")[0][:90]
            row["file"] = shown(path)
            rows.append(row)
        if not rows:
            continue
        found = True
        order = {name: i for i, name in enumerate(CONFIGS)}
        rows.sort(key=lambda r: (order.get(r["configuration"], 99), str(r["backend"]), r["resolution"] or 0))
        body += [f"<h3>{esc(case)}</h3>", table(rows)]
        convergence = front_convergence(runs) if case.startswith("Martin & Moyce") else []
        if convergence:
            body += ["<p>Grid convergence of the front (the runs above, from their CSV): the difference "
                     "between successive resolutions, which shrinks where the solution converges, whatever "
                     "its distance from the experiment.</p>", table(convergence)]
        pictures = []
        for r in rows:
            png = Path(r["file"]).with_suffix(".png")
            if png.is_file() and case != "Martin & Moyce 1952 (front Z)":
                check_png(png)
                target = page.out / f"{png.parent.name}_{png.name}"
                if png.resolve() != target.resolve():
                    shutil.copyfile(png, target)
                pictures.append(f'<p>{esc(r["configuration"])}, resolution {esc(r["resolution"])}, {esc(r["backend"])}:'
                                f'</p><p><img src="{esc(target.name)}" alt="{esc(png.name)}"></p>')
        if pictures:
            body.append(details(f"{len(pictures)} pictures", "\n".join(pictures)))
    if not found:
        body.append(page.missing("sphcore validate dam-break-pressure --out {dir} [--config engineering]"))
    if page.skipped:
        body.append("<p>JSON files under the results folders not read: " + "; ".join(
            f"{page.link(p)}: {esc(why)}" for p, why in page.skipped) + ".</p>")
    body.append("<p>Martin &amp; Moyce's residual column H is not compared: no measured H series is carried in "
                "validation/data (the front Z is).</p>")
    page.add("model", "The model: today's against the recommended (issue 12)", "\n".join(body))


def other_sections(page):
    for prefix, (title, command) in OTHER_SECTIONS.items():
        parts = page.files(prefix)
        page.add(prefix, title, "\n".join(parts) if parts else page.missing(command))


# ---- environment ----

def git_commit():
    """The checkout's commit, and whether the working tree differs from it; or why there is none."""
    if not (REPO / ".git").exists():
        return "not a git checkout"
    try:
        run = lambda *a: subprocess.run(["git", "-C", str(REPO), *a], capture_output=True, text=True,  # noqa: E731
                                        timeout=20, check=True).stdout.strip()
        commit = run("rev-parse", "HEAD")
        changed = run("status", "--porcelain", "--untracked-files=no").splitlines()
    except (OSError, subprocess.SubprocessError) as e:
        return f"unknown ({type(e).__name__})"
    return commit + (f" (the working tree differs from it in {len(changed)} tracked files)" if changed else "")


def versions():
    out = {"sphcore": _version("sphcore"), "git commit": git_commit(), "python": platform.python_version()}
    out.update({name: _version(name) for name in PACKAGES})
    return out


def _version(name):
    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return "not installed"


def cpu_model():
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def memory_gib():
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2 ** 30
    except (ValueError, OSError, AttributeError):
        return None


def vulkan_devices():
    """One dict per Vulkan device (name, type, API, driver), or a one-line reason there is none."""
    try:
        import vulkan as vk

        from sphcore.vk_runner import Context
        ctx = Context()
    except Exception as e:  # noqa: BLE001 - no loader, no driver, no package: said in the report
        return f"no Vulkan device could be opened: {type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''}"
    try:
        devices = []
        for d in vk.vkEnumeratePhysicalDevices(ctx.instance):
            p = vk.vkGetPhysicalDeviceProperties(d)
            api = p.apiVersion
            devices.append({"name": text(vk, p.deviceName), "type": ctx._type_name(p.deviceType),
                            "vendor id": hex(p.vendorID), "API": f"{api >> 22}.{(api >> 12) & 0x3ff}.{api & 0xfff}",
                            "driver": driver(vk, d, p), "float64 in shaders":
                                bool(vk.vkGetPhysicalDeviceFeatures(d).shaderFloat64),
                            "used by default": text(vk, p.deviceName) == ctx.device_name})
        return devices
    finally:
        ctx.close()


def text(vk, value):
    """A Vulkan char array as str (the vulkan package converts some, not those of structs we fill)."""
    return value if isinstance(value, str) else vk.ffi.string(value).decode()


def driver(vk, device, props):
    """The driver's name and version string (Vulkan 1.2's driver properties), else its version number."""
    v = props.driverVersion
    number = (f"{v >> 22}.{(v >> 14) & 0xff}.{(v >> 6) & 0xff}" if props.vendorID == 0x10DE  # NVIDIA's packing
              else f"{v >> 22}.{(v >> 12) & 0x3ff}.{v & 0xfff}")
    try:
        drv = vk.VkPhysicalDeviceDriverProperties(sType=vk.VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_DRIVER_PROPERTIES)
        vk.vkGetPhysicalDeviceProperties2(device, vk.VkPhysicalDeviceProperties2(
            sType=vk.VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_PROPERTIES_2, pNext=drv))
        name, info = text(vk, drv.driverName), text(vk, drv.driverInfo)
    except Exception:  # noqa: BLE001 - a device or loader before Vulkan 1.2: the number alone
        name = info = ""
    return f"{name} {info} (version {number})".strip() if name else f"version {number}"


def hardware():
    memory = memory_gib()
    return {"CPU": cpu_model(), "cores": os.cpu_count(),
            "cores usable": len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count(),
            "memory": f"{memory:.1f} GiB" if memory else "unknown", "system": platform.platform(),
            "host": platform.node()}


def environment(page, argv):
    devices = vulkan_devices()
    vk_part = table(devices) if isinstance(devices, list) else f"<p>{esc(devices)}</p>"
    body = ["<h3>Versions</h3>", key_values(versions()), "<h3>Hardware</h3>", key_values(hardware()),
            "<h3>Vulkan devices</h3>", vk_part,
            "<h3>This report</h3>", key_values({"command": argv, "results read from": ", ".join(map(shown, page.dirs)),
                                                 "generated": time.strftime("%Y-%m-%d %H:%M:%S %z")})]
    page.add("environment", "Run settings, versions and hardware", "\n".join(body))


def build_report(out, results=None, settings=None, argv=None):
    """Write DIR/index.html (and its pictures) from the results in `results` (a folder or a list
    of folders, searched in order) and DIR; return its path.
    `settings` overrides the 2D dam break's defaults where the report has to run it (for tests)."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    dirs = [Path(results)] if isinstance(results, (str, Path)) else [Path(r) for r in results or ()]
    for d in dirs:  # a typo would otherwise run the dam break into DIR and report that
        if not d.is_dir():
            raise ResultsError(f"--results {d}: {'not a folder' if d.exists() else 'no such folder'} (it takes a "
                               "folder the validation commands wrote into)")
    if out.resolve() not in [d.resolve() for d in dirs]:
        dirs.append(out)
    page = Page(out, dirs)
    dam_break_2d(page, settings)
    sweep_section(page)
    model_section(page)
    other_sections(page)
    environment(page, argv or " ".join(["sphcore", *sys.argv[1:]]))
    head = ("<p>Generated by <code>sphcore report</code>: every number and picture on this page comes from the "
            "files named in its section. Do not edit by hand; run the commands again.</p>")
    path = out / "index.html"
    atomic_write_bytes(path, page.html("sphcore validation report", head).encode())
    return path
