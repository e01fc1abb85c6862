"""Gauges declared in the scene ([[gauges]]): checked here, sampled on the device (shaders/sph/sample_gauges.comp,
in the plan after compute_forces), read back in chunks and written to RUN/gauges/NAME.csv.

    [[gauges]]
    name = "p_bottom"
    quantity = "pressure"   # pressure | velocity | density | height | force | moment
    at = [0.5, 0.03]        # pressure, velocity, density: a point; height: the foot of a vertical line
    # body = "tank"         # force and moment: on this body (scene key bodies); moment about `about`
    interval = 0.005        # simulated seconds between samples

The device keeps GAUGE_SLOTS samples a gauge in a ring (gauge_samples) and counts them (gauge_state); the host
(GaugeReader) reads the new ones at snapshots, checkpoints, the end, and before GAUGE_SLOTS steps have run since
its last read (a gauge samples at most once a step): never a read per step, and never a sample lost.
"""
import io
import math

import numpy as np

from sphcore.errors import SceneError, SimulationError

QUANTITIES = ("pressure", "velocity", "density", "height", "force", "moment")  # sample_gauges.comp's codes
POINT = ("pressure", "velocity", "density", "height")  # the quantities of a point (height: of a line's foot)
ON_BODY = ("force", "moment")
KEYS = ("name", "quantity", "at", "body", "about", "interval")
GAUGE_SLOTS = 256  # samples a gauge keeps on the device between reads (plan.BUFFERS: gauge_samples)
LAYER_SLOTS = 16  # on a rank, samples of a force's or moment's layer sums kept (gauge_layers; sample_gauges.comp)
MAX_GAUGES = 256
FOLDER = "gauges"  # RUN/gauges/NAME.csv


def columns(quantity, dim):
    """The CSV header's columns after `time [s]`: the quantity's components with their SI units (2D: forces
    and moments per metre of depth)."""
    axes = "xyz"[:dim]
    per = "/m" if dim == 2 else ""
    return {"pressure": ["p [Pa]"], "density": ["rho [kg/m^3]"], "height": ["height [m]"],
            "velocity": [f"v{a} [m/s]" for a in axes], "force": [f"F{a} [N{per}]" for a in axes],
            "moment": ["Mz [N m/m]"] if dim == 2 else [f"M{a} [N m]" for a in axes]}[quantity]


def _vector(where, value):
    if (not isinstance(value, list) or len(value) not in (2, 3)
            or any(isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) for v in value)):
        raise SceneError(f"{where}: expected [x, y] or [x, y, z] (m), got {value!r:.60}")
    return [float(v) for v in value]


def check_shape(where, value):
    """The [[gauges]] list of a scene, each table's keys and types checked (SceneError, one line naming the
    gauge and key); returns it in canonical form (numbers as floats)."""
    if not isinstance(value, list):
        raise SceneError(f"{where}: expected a list of [[gauges]] tables, got {value!r:.60}")
    if len(value) > MAX_GAUGES:
        raise SceneError(f"{where}: {len(value)} gauges, at most {MAX_GAUGES}")
    out = []
    for i, gauge in enumerate(value):
        here = f"{where}[{i}]"
        if not isinstance(gauge, dict):
            raise SceneError(f"{here}: expected a table (name, quantity, at, interval), got {gauge!r:.60}")
        unknown = sorted(set(gauge) - set(KEYS), key=str)
        if unknown:
            raise SceneError(f"{here}: unknown key {unknown[0]!r} (known: {', '.join(KEYS)})")
        name = gauge.get("name")
        if (not isinstance(name, str) or not name or name.startswith(".") or any(c in name for c in "/\\")
                or not name.isprintable()):
            raise SceneError(f"{here}.name = {name!r:.60}: must be a file name (gauges/NAME.csv: no /, \\, "
                             "leading dot)")
        here = f"{where}[{i}] ({name})"
        quantity = gauge.get("quantity")
        if quantity not in QUANTITIES:
            raise SceneError(f"{here}.quantity = {quantity!r:.60}: choose one of {', '.join(map(repr, QUANTITIES))}")
        interval = gauge.get("interval")
        if isinstance(interval, bool) or not isinstance(interval, (int, float)) or not 0 < interval <= 1e9:
            raise SceneError(f"{here}.interval = {interval!r:.60}: must be a number of seconds within (0, 1e9]")
        canonical = {"name": name, "quantity": quantity, "interval": float(interval)}
        if quantity in POINT:
            if "at" not in gauge:
                raise SceneError(f"{here}: a {quantity} gauge needs at = [x, y(, z)] (m)")
            canonical["at"] = _vector(f"{here}.at", gauge["at"])
        else:
            if not isinstance(gauge.get("body"), str):
                raise SceneError(f"{here}: a {quantity} gauge needs body = the name of one of the scene's bodies")
            canonical["body"] = gauge["body"]
        for key in ("at", "body", "about"):
            if key in gauge and key not in canonical and not (key == "about" and quantity == "moment"):
                raise SceneError(f"{here}.{key}: a {quantity} gauge takes no {key}")
        if "about" in gauge:
            canonical["about"] = _vector(f"{here}.about", gauge["about"])
        out.append(canonical)
    return out


def check_scene(gauges, dim, box_min, box_max, bodies):
    """The gauges against the scene: names unique, points of `dim` components inside the box, bodies among
    `bodies` (the names of the scene's bodies)."""
    seen = set()
    for i, gauge in enumerate(gauges):
        here = f"gauges[{i}] ({gauge['name']})"
        if gauge["name"] in seen:
            raise SceneError(f"{here}: a second gauge named {gauge['name']!r}: each writes gauges/NAME.csv")
        seen.add(gauge["name"])
        for key in ("at", "about"):
            if key in gauge and len(gauge[key]) != dim:
                raise SceneError(f"{here}.{key} = {gauge[key]} has {len(gauge[key])} components but "
                                 f"physics.dimension = {dim}")
        if "at" in gauge and any(not box_min[a] <= gauge["at"][a] <= box_max[a] for a in range(dim)):
            raise SceneError(f"{here}.at = {gauge['at']} is outside the domain {box_min} .. {box_max}")
        if "body" in gauge and gauge["body"] not in bodies:
            known = f"the scene's bodies: {', '.join(bodies)}" if bodies else "the scene has no bodies"
            raise SceneError(f"{here}.body = {gauge['body']!r}: no such body ({known})")


def vertical_axis(scene):
    """The axis of a height gauge's line: the one gravity mostly points along (as Scene.hydrostatic_pressure), y
    without gravity. The line goes up it, toward domain.box_max."""
    g = np.asarray(scene["forces.gravity"], np.float64)
    return int(np.argmax(np.abs(g))) if scene["physics.gravity"] and g.any() else 1


def table(scene, bodies=None):
    """(gauge_table, gauge_state) of the scene's gauges (plan.empty_state's `gauges`; layouts in plan.BUFFERS),
    or None without gauges. `bodies`: name -> (first particle id, count, centre) of the scene's bodies, for the
    force and moment gauges (a moment is about `about`, else the body's centre)."""
    gauges = scene.config.get("gauges", [])
    if not gauges:
        return None
    rows = np.zeros((2 * len(gauges), 4), np.float32)
    state = np.zeros((2 * len(gauges), 4), np.uint32)
    for g, gauge in enumerate(gauges):
        quantity = gauge["quantity"]
        rows[2 * g, :scene.dim] = gauge.get("at", [0.0] * scene.dim)
        rows[2 * g, 3] = gauge["interval"]
        rows[2 * g + 1, 3] = scene.mass
        state[2 * g] = (QUANTITIES.index(quantity), 0, 0, GAUGE_SLOTS)
        if quantity == "height":  # the step along the line, dx / 2, and its axis: gravity's (vertical_axis)
            rows[2 * g + 1, 0] = scene["fluid.spacing"] / 2
            state[2 * g, 1] = vertical_axis(scene)
        if quantity in ON_BODY:
            first, count, centre = (bodies or {})[gauge["body"]]
            state[2 * g, 1:3] = (first, count)
            rows[2 * g + 1, :scene.dim] = gauge.get("about", list(centre)[:scene.dim])
    return rows, state


class GaugeReader:
    """The samples the device took since the last read, per gauge: `read(backend)` returns a list of arrays
    (rows, 1 + components) in float64, time first. `since` counts the steps since the last read, which must stay
    below GAUGE_SLOTS (Simulation.advance reads before)."""

    def __init__(self, scene, state):
        self.names = [g["name"] for g in scene.config["gauges"]]
        # the columns of gauge_samples each gauge's CSV takes: time, then its components (2D: a moment's is z)
        self.columns = [[0, 3] if g["quantity"] == "moment" and scene.dim == 2
                        else list(range(1 + len(columns(g["quantity"], scene.dim)))) for g in scene.config["gauges"]]
        self.taken = np.asarray(state)[1::2, 1].astype(np.int64)  # samples read so far, per gauge
        self.on_body = [g["quantity"] in ON_BODY for g in scene.config["gauges"]]
        self.since = 0

    def slots(self, layers=0):
        """The samples each gauge's ring on the device holds: GAUGE_SLOTS, or with `layers` (on a rank) LAYER_SLOTS
        for a force or moment, whose layers' sums gauge_layers keeps."""
        return np.where(np.array(self.on_body, bool) & bool(layers), LAYER_SLOTS, GAUGE_SLOTS)

    def read(self, backend):
        return self.kept(self.samples(backend))

    def kept(self, samples):
        """Of each gauge's `samples` (rows of time, x, y, z) the columns of its CSV."""
        return [rows[:, kept] for rows, kept in zip(samples, self.columns)]

    def samples(self, backend, layers=0):
        """The new samples of each gauge as the device wrote them: (rows, 4) arrays of time, x, y, z. With `layers`
        (on a rank of sphcore.parallel: the grid's cell layers), (those, and each force's or moment's sums over
        each layer for them: (rows, layers, 3) arrays in the buffers' precision, None for the other gauges)."""
        state = np.asarray(backend.read_buffer("gauge_state"))
        taken = state[1::2, 1].astype(np.int64)
        new = taken - self.taken
        slots = self.slots(layers)
        if (new > slots).any() or (new < 0).any():
            g = int(np.argmax((new > slots) | (new < 0)))
            raise SimulationError(f"gauge {self.names[g]!r}: {int(new[g])} samples since the last read, its ring "
                                  f"on the device holds {slots[g]}: samples were lost")
        rows = [np.zeros((0, 4)) for _ in self.columns]
        sums = [np.zeros((0, layers, 3)) if on_body else None for on_body in self.on_body]
        if new.any():
            samples = np.asarray(backend.read_buffer("gauge_samples"), np.float64).reshape(len(taken), GAUGE_SLOTS, 4)
            for g in range(len(rows)):
                rows[g] = samples[g][np.arange(self.taken[g], taken[g]) % GAUGE_SLOTS]
            if layers and any(self.on_body):
                ring = backend.read_buffer("gauge_layers")[:len(taken) * LAYER_SLOTS * layers]
                ring = ring.reshape(len(taken), LAYER_SLOTS, layers, 4)
                for g in np.flatnonzero(self.on_body):
                    sums[g] = ring[g][np.arange(self.taken[g], taken[g]) % LAYER_SLOTS, :, :3]
        self.taken, self.since = taken, 0
        return (rows, sums) if layers else rows


def merged(scene, ranks):
    """The samples of each gauge from those of every rank of sphcore.parallel (`ranks`: GaugeReader.samples(backend,
    layers) of each, in rank order), as one rank takes them: a rank samples what lies in its slab, the time -1 where
    it took nothing (sample_gauges.comp). A point's sample is the one rank's whose slab holds it; a height's, the
    highest rank's that found the surface (value y 1: the slabs go up the line in rank order where it runs along
    their axis, and lie beside it where not), else 0 (at the time of a rank's that took it). A force or moment is
    the sum of its layers' sums, added over the ranks (one rank's each, the others' 0) and then along the layers in
    the buffers' precision, times the mass, as the shader adds them on one rank: the same bits whatever the cuts.
    SimulationError where no rank took a sample."""
    out = []
    for g, gauge in enumerate(scene.config["gauges"]):
        counts = {len(samples[g]) for samples, _ in ranks}
        if len(counts) > 1:
            raise SimulationError(f"gauge {gauge['name']!r}: the ranks took {sorted(counts)} samples, not as many")
        rows = np.stack([samples[g] for samples, _ in ranks])  # (ranks, samples, 4)
        took = rows[:, :, 0] >= 0
        if not took.any(axis=0).all():
            raise SimulationError(f"gauge {gauge['name']!r}: no rank took one of its samples (no slab held "
                                  f"{gauge.get('at')})")
        pick = np.argmax(took, axis=0)  # (a point's: the first rank that took it, the only one)
        if gauge["quantity"] == "height":
            found = took & (rows[:, :, 2] == 1)
            highest = len(ranks) - 1 - np.argmax(found[::-1], axis=0)
            pick = np.where(found.any(axis=0), highest, pick)
        taken = rows[pick, np.arange(rows.shape[1])]
        if gauge["quantity"] in ON_BODY:
            sums = ranks[0][1][g]  # (samples, layers, 3)
            for _, other in ranks[1:]:
                sums = sums + other[g]  # (x + 0 is x: one rank's sum each)
            total = np.zeros((len(taken), 3), sums.dtype)
            for layer in range(sums.shape[1]):
                total = total + sums[:, layer]
            taken[:, 1:] = sums.dtype.type(np.float32(scene.mass)) * total  # (the mass as gauge_table holds it)
        out.append(taken)
    return out


def csv_text(quantity, dim, rows, header=True):
    """CSV lines of `rows` (time, components), with the header line first where `header`."""
    out = io.StringIO()
    if header:
        out.write(",".join(["time [s]"] + columns(quantity, dim)) + "\n")
    for row in rows:
        out.write(",".join(repr(float(v)) for v in row) + "\n")
    return out.getvalue()


class GaugeFiles:
    """RUN/gauges/NAME.csv of each gauge, written through the run's folder (sphcore.folder.RunFolder: locked,
    in its manifest, each write atomic: a file is its header and whole rows, never half a row). A resumed run
    keeps the first `taken` rows of each (the samples its checkpoint had counted: rows past it are of steps
    that run again) and appends."""

    def __init__(self, run_folder, scene, taken=None):
        self.folder, self.dim = run_folder, scene.dim
        self.gauges = scene.config["gauges"]
        self.text = []
        for g, gauge in enumerate(self.gauges):
            kept = ""
            if taken is not None:
                try:
                    lines = (run_folder.path / self.name(gauge)).read_text().splitlines(keepends=True)[1:]
                except OSError:
                    lines = []
                kept = "".join(lines[:int(taken[g])])
            self.text.append(csv_text(gauge["quantity"], self.dim, []) + kept)
        self.dirty = True

    @staticmethod
    def name(gauge):
        return f"{FOLDER}/{gauge['name']}.csv"

    def add(self, rows):
        for g, gauge_rows in enumerate(rows):
            if len(gauge_rows):
                self.text[g] += csv_text(self.gauges[g]["quantity"], self.dim, gauge_rows, header=False)
                self.dirty = True

    def write(self):
        if self.dirty:
            for gauge, text in zip(self.gauges, self.text):
                self.folder.write_bytes(self.name(gauge), text.encode())
            self.dirty = False


def read_csv(path):
    """(header columns, rows as a float64 array) of a gauge's CSV."""
    with open(path) as f:
        header = f.readline().rstrip("\n").split(",")
        rows = [[float(v) for v in line.split(",")] for line in f if line.strip()]
    return header, np.array(rows, np.float64).reshape(-1, len(header))
