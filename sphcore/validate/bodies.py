"""Bodies, wall particles and gauges (issue 33): water at rest in tanks made of [[bodies]] and a dam break in a
tank inclined to the lattice, each measured by the scene's own [[gauges]] (RUN/gauges/*.csv) where a gauge can
measure it. The engineering model (physics.model = "engineering": Wendland C2 on h = 4 dx, continuity density
starting hydrostatic, Adami, Hu & Adams 2012's wall particles) throughout.

- rotated_tank: a 2D rectangular tank WIDTH x HEIGHT (a polygon container), rotated by ANGLE degrees about its
  centre, filled by a block up to its centre's height that the clipping cuts to the tank (gravity -y: the free
  surface is horizontal from the start). Pressure gauges on a vertical line at a quarter, half and three quarters
  of its depth against rho_0 g depth, the depth from a height gauge on the same line; target within 3 %. No fluid
  particle outside the tank at the end: signed distance (sphcore.geometry.signed_distance) > -dx / 2.
- cylindrical_tank: 3D, scenes/meshes/cylinder_tank.stl (radius 0.3 m, height 0.6 m) as a container, filled to
  FILL; a pressure gauge on its axis near the floor and a height gauge; the same targets.
- forces_at_rest: a 2D tank of three bodies (floor, left wall, right wall), each with a force gauge. The floor's
  force against the water's weight (target 1 %), each side wall's against rho_0 g H^2 / 2 per metre (target 3 %),
  H from a height gauge. The bodies meet along the diagonals of the corners: the wall particles of a corner
  take a force both down and sideways, and a floor under the side walls took all of it (the side walls read
  5.4 % low at 15 particles per depth; split at the diagonal, 3.9 %).
- inclined_dam_break: Martin & Moyce 1952's column (sphcore.validate.dam_break) in a tank that is a polygon body
  rotated by ANGLE, gravity rotated with it: in the tank's frame the flow is the box run's. A front is not a gauge
  quantity: it is measured from the particles as dam_break.measure does, in the tank's frame, every sample.
  The column: a fluid block is axis-aligned, and an extra body to cut a rotated column out of one would stay as
  a wall (bodies are fixed), so the column is given as one block per lattice column (a strip dx wide holding the
  lattice points whose centre lies in the rotated column), then clipped to the tank as any block. Its density
  starts hydrostatic in the tank's frame, rho_0 g (2a - y') (the box run's start): Scene.hydrostatic_pressure
  measures depth along the grid axis gravity mostly points along, which a rotated gravity is not, so the
  initial densities are set through a checkpoint (Simulation.checkpoint / restore) before the first step.
  Reported beside the box run of dam_break.py (mirror walls) with the engineering configuration at the same
  resolution, and, as a control, the same body-tank run unrotated (angle 0). No target.

"Settled": the mean over the second half of the run (t >= t_end / 2); the last sample is reported too.
"""
import math
import tempfile
import time
from pathlib import Path

import numpy as np

from sphcore import geometry
from sphcore.gauges import read_csv
from sphcore.paths import SCENE_DIR
from sphcore.scene import Scene, SceneError
from sphcore.validate import dam_break
from sphcore.validate.buchner import sampled_run, stop, write_results

G = 9.81
RHO0 = 1000.0
MESHES = SCENE_DIR / "meshes"
TARGETS = {"pressure": 0.03, "outside_dx": -0.5, "floor_force": 0.01, "wall_force": 0.03}

SETTINGS = {  # what `sphcore validate bodies` runs, case by case
    "rotated_tank": {"spacing": 0.01, "t_end": 1.0, "angle": 30.0, "width": 1.0, "height": 0.6},
    "cylindrical_tank": {"spacing": 0.035, "t_end": 2.0, "fill": 0.4},
    "forces_at_rest": {"spacing": 0.01, "t_end": 1.0, "width": 0.6, "depth": 0.3},
    "inclined_dam_break": {"resolution": 40, "t_end": 0.5, "angle": 30.0, "control": True},
}
COMMON = {"backend": "numba", "device": None}
INTERVAL = 0.01  # s between gauge samples


def on_lattice(value, dx):
    """`value` (a number or an array) rounded to a multiple of dx."""
    return np.round(np.asarray(value, np.float64) / dx) * dx


def settled(t, values, t_end):
    """The mean of `values` (rows) over the second half of the run."""
    return np.asarray(values)[np.asarray(t) >= t_end / 2].mean(axis=0)


def run_scene(scene, s, progress):
    """sphcore.run of `scene` into a temporary folder: (final arrays, {gauge name: (header, rows)})."""
    from sphcore.runner import run

    options = {"device": s["device"]} if s["backend"] == "vulkan" and s["device"] is not None else {}
    with tempfile.TemporaryDirectory(prefix="sphcore-bodies-") as tmp:
        start = time.perf_counter()
        final = run(scene, s["backend"], out_dir=tmp, progress=progress, **options)
        wall = time.perf_counter() - start
        gauges = {p.stem: read_csv(p) for p in (Path(tmp) / "gauges").glob("*.csv")}
    return final, gauges, wall


def check(s, key, low):
    if not (isinstance(s[key], (int, float)) and s[key] > low):
        raise SceneError(f"{key} = {s[key]!r}: must be a number > {low}")


# ---- cases 1 and 2: water at rest in a rotated tank, in a cylinder ----

def rotated_tank_scene(s):
    """The rotated tank (module docstring) and its gauge points: (scene, points {name: (x, y)}, foot)."""
    for key in ("spacing", "t_end", "width", "height"):
        check(s, key, 0)
    dx, w, hh, angle = s["spacing"], s["width"], s["height"], s["angle"]
    h = 4 * dx
    r = geometry.rotation(angle)
    corners = np.array([[-w / 2, -hh / 2], [w / 2, -hh / 2], [w / 2, hh / 2], [-w / 2, hh / 2]]) @ r.T
    centre = on_lattice(np.abs(corners).max(axis=0) + h + 2 * dx, dx)
    box = 2 * centre
    surface = float(centre[1])  # the block's top, on the lattice: the tank's half below it
    # the gauges' vertical line, at a tenth of the width left of the centre, from the tank's floor
    x_line = float(centre[0] - 0.1 * w)
    floor = lowest_inside(corners + centre, x_line)
    depth = surface - floor
    points = {f"p{round(100 * f)}": (x_line, surface - f * depth) for f in (0.25, 0.5, 0.75)}
    data = {
        "name": "rotated_tank", "physics": {"model": "engineering", "dimension": 2},
        "domain": {"box_min": [0.0, 0.0], "box_max": box.tolist()},
        "fluid": {"spacing": dx, "blocks": [{"min": [0.0, 0.0], "max": [float(box[0]), float(surface)]}]},
        "forces": {"gravity": [0.0, -G]},
        "bodies": [{"name": "tank", "polygon": [[-w / 2, -hh / 2], [w / 2, -hh / 2], [w / 2, hh / 2], [-w / 2, hh / 2]],
                    "rotate": angle, "translate": centre.tolist(), "fluid": "inside"}],
        "time": {"end": s["t_end"], "output_interval": s["t_end"]},
        "gauges": [*({"name": k, "quantity": "pressure", "at": list(v), "interval": INTERVAL} for k, v in points.items()),
                   {"name": "level", "quantity": "height", "at": [x_line, floor], "interval": INTERVAL}],
    }
    return Scene.from_dict(data, source="rotated tank"), points


def lowest_inside(polygon, x):
    """The lowest y of the vertical line at x inside `polygon`."""
    import shapely

    (x0, y0, x1, y1) = shapely.Polygon(polygon).bounds
    line = shapely.LineString([(x, y0 - 1), (x, y1 + 1)]).intersection(shapely.Polygon(polygon))
    return float(line.bounds[1])


def cylinder_scene(s):
    """The cylindrical tank (module docstring): (scene, points)."""
    for key in ("spacing", "t_end", "fill"):
        check(s, key, 0)
    dx, fill = s["spacing"], s["fill"]
    radius, height, h = 0.3, 0.6, 4 * dx
    c = float(on_lattice(radius + h + 2 * dx, dx))
    base = float(on_lattice(h + 2 * dx, dx))
    box = [2 * c, base + height + 2 * dx, 2 * c]
    surface = base + float(on_lattice(fill, dx))
    points = {"p_floor": (c, base + 0.25 * fill, c), "p_mid": (c, base + 0.5 * fill, c)}
    data = {
        "name": "cylindrical_tank", "physics": {"model": "engineering", "dimension": 3},
        "domain": {"box_min": [0.0, 0.0, 0.0], "box_max": box},
        "fluid": {"spacing": dx, "blocks": [{"min": [0.0, 0.0, 0.0], "max": [box[0], surface, box[2]]}]},
        "forces": {"gravity": [0.0, -G, 0.0]},
        "bodies": [{"name": "tank", "mesh": str(MESHES / "cylinder_tank.stl"), "translate": [c, base, c],
                    "fluid": "inside"}],
        "time": {"end": s["t_end"], "output_interval": s["t_end"]},
        "gauges": [*({"name": k, "quantity": "pressure", "at": list(v), "interval": INTERVAL} for k, v in points.items()),
                   {"name": "level", "quantity": "height", "at": [c, base, c], "interval": INTERVAL}],
    }
    return Scene.from_dict(data, source="cylindrical tank"), points


def water_at_rest(case, scene, points, s, out_dir, progress):
    """Run a tank at rest; its pressure gauges against rho_0 g depth, depth below the free surface of the fluid at
    the end (fluid_surface, on the height gauge's line; see there why not the height gauge's own reading)."""
    final, gauges, wall = run_scene(scene, s, progress)
    up = 1  # (y: gravity -y)
    foot = scene.config["gauges"][-1]["at"]
    x = final["position"].astype(np.float64)
    surface = fluid_surface(scene, x, foot)
    t = gauges["level"][1][:, 0]
    rows, errors, last = [], {}, {}
    for i, ti in enumerate(t):
        row = {"t": ti, "height_gauge_m": foot[up] + gauges["level"][1][i, 1]}
        for k, point in points.items():
            row.update({f"{k}_pa": gauges[k][1][i, 1], f"{k}_hydrostatic_pa": RHO0 * G * (surface - point[up])})
        rows.append(row)
    for k, point in points.items():
        p = float(settled(t, gauges[k][1][:, 1], s["t_end"]))
        errors[k] = p / (RHO0 * G * (surface - point[up])) - 1
        last[k] = rows[-1][f"{k}_pa"] / rows[-1][f"{k}_hydrostatic_pa"] - 1
    dx = scene["fluid.spacing"]
    outside = float(geometry.signed_distance(scene.bodies[0], x).min()) / dx
    summary = {"case": case, "settings": s, "particles": len(x), "walls": len(scene.wall_positions()[0]),
               "wall_s": wall, "steps": int(final["step"]), "dx": dx, "h": scene.h,
               "points": {k: list(v) for k, v in points.items()}, "surface_m": surface,
               "surface_from_volume_m": volume_level(scene, len(x)),
               "height_gauge_settled_m": float(settled(t, [r["height_gauge_m"] for r in rows], s["t_end"])),
               "pressure_errors_settled": errors, "pressure_errors_last": last,
               "pressure_error_max": max(abs(v) for v in errors.values()),
               "closest_to_wall_dx": outside, "settled_over": [s["t_end"] / 2, s["t_end"]], "targets": TARGETS,
               "meets": {"pressure": bool(max(abs(v) for v in errors.values()) <= TARGETS["pressure"]),
                         "inside": bool(outside > TARGETS["outside_dx"])}}
    if out_dir is not None:
        write_results(rows, summary, out_dir, case)
    return rows, summary


def wendland(q):
    """Wendland C2's shape at q = r / h, 2D and 3D (its normalisation cancels in fluid_surface's ratio)."""
    q = np.minimum(q, 1.0)
    return (1 - q) ** 4 * (1 + 4 * q)


def fluid_surface(scene, x, foot):
    """The free surface above `foot` as the height gauge defines it (sample_gauges.comp: the highest point of the
    vertical line where the mass sum falls below rho_0 / 2, every dx / 2, linear between), over the fluid
    particles x only (the gauge itself, since its sums leave the wall particles out, reads the same surface within
    a few mm: the JSON gives both). The mass sum is
    m sum W, m the lattice mass (a full lattice sums to rho_0): here sum W over that of a full lattice."""
    dx, h, dim = scene["fluid.spacing"], scene.h, scene.dim
    k = np.arange(-math.ceil(h / dx), math.ceil(h / dx) + 1) * dx
    grid = np.stack(np.meshgrid(*[k] * dim), axis=-1).reshape(-1, dim)
    full = wendland(np.sqrt((grid ** 2).sum(1)) / h).sum()
    near = x[np.abs(x[:, [a for a in range(dim) if a != 1]] - np.delete(foot, 1)).max(axis=1) < h]
    levels = np.arange(foot[1], scene["domain.box_max"][1], dx / 2)
    at = np.repeat(np.asarray(foot, np.float64)[None], len(levels), axis=0)
    at[:, 1] = levels
    ratio = wendland(np.sqrt(((at[:, None, :] - near[None]) ** 2).sum(-1)) / h).sum(1) / full
    cross = np.flatnonzero((ratio[:-1] >= 0.5) & (ratio[1:] < 0.5))
    if not len(cross):
        return math.nan
    i = cross[-1]
    return float(levels[i] + (levels[i + 1] - levels[i]) * (ratio[i] - 0.5) / (ratio[i] - ratio[i + 1]))


def volume_level(scene, n):
    """The free surface's height from the water's incompressible volume n dx^dim in the container (a reference
    beside fluid_surface): 2D, the level below which the polygon holds that area; 3D, the container's floor plus
    the volume over its cross-section at mid-height (exact for a prism, as the cylinder)."""
    body = scene.bodies[0]
    need = n * scene["fluid.spacing"] ** scene.dim
    lo, hi = body.bounds[0][1], body.bounds[1][1]
    if body.dim == 3:
        section = body.shape.section(plane_origin=[0.0, (lo + hi) / 2, 0.0], plane_normal=[0.0, 1.0, 0.0])
        return float(lo + need / section.to_planar()[0].area)
    import shapely

    (x0, y0), (x1, _) = body.bounds
    for _ in range(50):
        mid = (lo + hi) / 2
        area = body.shape.intersection(shapely.box(x0 - 1, y0 - 1, x1 + 1, mid)).area
        lo, hi = (mid, hi) if area < need else (lo, mid)
    return float((lo + hi) / 2)


def run_rotated_tank(settings=None, out_dir=None, progress=True):
    s = {**COMMON, **SETTINGS["rotated_tank"], **(settings or {})}
    scene, points = rotated_tank_scene(s)
    return water_at_rest("rotated_tank", scene, points, s, out_dir, progress)


def run_cylindrical_tank(settings=None, out_dir=None, progress=True):
    s = {**COMMON, **SETTINGS["cylindrical_tank"], **(settings or {})}
    scene, points = cylinder_scene(s)
    return water_at_rest("cylindrical_tank", scene, points, s, out_dir, progress)


# ---- case 3: the forces on a tank of three bodies ----

def forces_scene(s):
    for key in ("spacing", "t_end", "width", "depth"):
        check(s, key, 0)
    dx, w, d = s["spacing"], s["width"], s["depth"]
    h = 4 * dx
    x0 = y0 = float(on_lattice(h + dx, dx))  # the inside's lower left corner, h of wall around it
    x1, top = x0 + float(on_lattice(w, dx)), y0 + float(on_lattice(2 * d, dx))
    box = [x1 + x0, top + dx]
    surface = y0 + float(on_lattice(d, dx))
    data = {
        "name": "forces_at_rest", "physics": {"model": "engineering", "dimension": 2},
        "domain": {"box_min": [0.0, 0.0], "box_max": box},
        "fluid": {"spacing": dx, "blocks": [{"min": [x0, y0], "max": [x1, surface]}]},
        "forces": {"gravity": [0.0, -G]},
        "bodies": [{"name": "floor", "polygon": [[0.0, 0.0], [box[0], 0.0], [x1, y0], [x0, y0]]},
                   {"name": "left", "polygon": [[0.0, 0.0], [x0, y0], [x0, top], [0.0, top]]},
                   {"name": "right", "polygon": [[box[0], 0.0], [box[0], top], [x1, top], [x1, y0]]}],
        "time": {"end": s["t_end"], "output_interval": s["t_end"]},
        "gauges": [*({"name": f"F_{b}", "quantity": "force", "body": b, "interval": INTERVAL}
                     for b in ("floor", "left", "right")),
                   {"name": "level", "quantity": "height", "at": [(x0 + x1) / 2, y0], "interval": INTERVAL}],
    }
    return Scene.from_dict(data, source="forces at rest")


def run_forces_at_rest(settings=None, out_dir=None, progress=True):
    """The floor's force against the weight, each side wall's against rho_0 g H^2 / 2 (module docstring)."""
    s = {**COMMON, **SETTINGS["forces_at_rest"], **(settings or {})}
    scene = forces_scene(s)
    final, gauges, wall = run_scene(scene, s, progress)
    n = len(final["position"])
    weight = scene.mass * n * G
    t, level = gauges["level"][1][:, 0], gauges["level"][1][:, 1]
    floor, left, right = (gauges[f"F_{b}"][1] for b in ("floor", "left", "right"))
    rows = [{"t": t[i], "level_m": level[i], "floor_fy": floor[i, 2], "left_fx": left[i, 1], "right_fx": right[i, 1],
             "weight": weight, "side_hydrostatic": RHO0 * G * level[i] ** 2 / 2} for i in range(len(t))]
    depth = float(settled(t, level, s["t_end"]))
    side = RHO0 * G * depth ** 2 / 2
    f = {k: float(settled(t, v, s["t_end"])) for k, v in (("floor", -floor[:, 2]), ("left", -left[:, 1]),
                                                              ("right", right[:, 1]))}
    errors = {"floor": f["floor"] / weight - 1, "left": f["left"] / side - 1, "right": f["right"] / side - 1}
    x = final["position"].astype(np.float64)
    closest = min(float(geometry.signed_distance(b, x).min()) for b in scene.bodies) / scene["fluid.spacing"]
    summary = {"case": "forces_at_rest", "settings": s, "particles": n, "walls": len(scene.wall_positions()[0]),
               "wall_s": wall, "steps": int(final["step"]), "dx": scene["fluid.spacing"], "h": scene.h,
               "weight_n_per_m": weight, "depth_settled_m": depth, "depth_from_volume_m": n * scene["fluid.spacing"] ** 2
               / on_lattice(s["width"], scene["fluid.spacing"]), "side_target_n_per_m": side,
               "forces_settled_n_per_m": f, "force_errors_settled": errors, "closest_to_wall_dx": closest,
               "settled_over": [s["t_end"] / 2, s["t_end"]], "targets": TARGETS,
               "meets": {"floor_force": bool(abs(errors["floor"]) <= TARGETS["floor_force"]),
                         "wall_force": bool(max(abs(errors["left"]), abs(errors["right"])) <= TARGETS["wall_force"]),
                         "inside": bool(closest > TARGETS["outside_dx"])}}
    if out_dir is not None:
        write_results(rows, summary, out_dir, "forces_at_rest")
    return rows, summary


# ---- case 4: Martin & Moyce in an inclined tank ----

def inclined_scene(s, angle):
    """The dam break's tank (8a x 2.4a, dam_break.py) as a polygon body rotated by `angle` about its lower left
    corner, gravity rotated with it, the column as strips of the lattice (module docstring): (scene, rotation,
    corner). Model and stiffness as dam_break.py's engineering run."""
    if not (isinstance(s["resolution"], int) and s["resolution"] >= 8):
        raise SceneError(f"resolution = {s['resolution']!r}: particles across a, an integer >= 8")
    check(s, "t_end", 0)
    a = dam_break.SETTINGS["a"]
    dx = a / s["resolution"]
    h = 4 * dx
    r = geometry.rotation(angle)
    length, height = dam_break.TANK_LENGTH * a, dam_break.TANK_HEIGHT * a
    tank = np.array([[0.0, 0.0], [length, 0.0], [length, height], [0.0, height]])
    world = tank @ r.T
    corner = on_lattice(-world.min(axis=0) + h + 2 * dx, dx)  # where the tank's corner goes in the box
    box = on_lattice(world.max(axis=0) + corner + h + 2 * dx, dx)
    n = np.round(box / dx).astype(int)
    xc = (np.arange(n[0]) + 0.5) * dx
    yc = (np.arange(n[1]) + 0.5) * dx
    blocks = []
    for i, x in enumerate(xc):
        local = (np.stack([np.full_like(yc, x), yc], axis=1) - corner) @ r  # (the tank's frame)
        inside = np.flatnonzero((local[:, 0] > 0) & (local[:, 0] <= a) & (local[:, 1] > 0) & (local[:, 1] <= 2 * a))
        if len(inside):
            blocks.append({"min": [i * dx, inside[0] * dx], "max": [(i + 1) * dx, (inside[-1] + 1) * dx]})
    gravity = (r @ np.array([0.0, -G])).tolist()
    stiffness = dam_break.SETTINGS["stiffness"]
    data = {
        "name": "inclined_dam_break", "physics": {"model": "engineering", "dimension": 2},
        "domain": {"box_min": [0.0, 0.0], "box_max": box.tolist()},
        "fluid": {"spacing": dx, "blocks": blocks, "stiffness": stiffness},
        "forces": {"gravity": gravity},
        "bodies": [{"name": "tank", "polygon": tank.tolist(), "rotate": angle, "translate": corner.tolist(),
                    "fluid": "inside"}],
        "time": {"dt": "auto", "steps": 1},
    }
    return Scene.from_dict(data, source="inclined dam break"), r, corner


def start_hydrostatic(sim, scene, r, corner, a):
    """Set the fluid's density to the column's hydrostatic rho_0 + rho_0 g (2a - y') / k in the tank's frame
    (linear law), through a checkpoint; the wall particles' density is the wall stage's every step."""
    arrays = sim.checkpoint()
    arrays.pop("energy_start")  # (the initial energy changes with the densities: not a resume's check)
    x = arrays["buffer_particle_x"][:, :2].astype(np.float64)
    depth = np.maximum(2 * a - ((x - corner) @ r)[:, 1], 0.0)
    rho = RHO0 + RHO0 * G * depth / scene["fluid.stiffness"]
    fluid = arrays["buffer_particle_id"] < sim.fluid_count
    arrays["buffer_particle_rho"] = np.where(fluid, rho, arrays["buffer_particle_rho"]).astype(
        arrays["buffer_particle_rho"].dtype)
    sim.restore(arrays)


def run_inclined(s, angle, progress):
    """One run of the inclined dam break at `angle`: (rows, info) as dam_break.run_dam_break's."""
    from sphcore.simulation import Simulation

    scene, r, corner = inclined_scene(s, angle)
    a = dam_break.SETTINGS["a"]
    dt = dam_break.dt_estimate(scene)
    every = max(1, round(dam_break.SAMPLE_DT / math.sqrt(2 * G / a) / dt))
    steps = math.ceil(s["t_end"] / dt)
    options = {"device": s["device"]} if s["backend"] == "vulkan" and s["device"] is not None else {}
    sim = Simulation(scene, s["backend"], **options)
    k_min = dam_break.min_neighbours(scene)

    def sample(sim):  # (the front and the column in the tank's frame)
        front, column = dam_break.measure(scene, (sim.read()["particle_x"].astype(np.float64) - corner) @ r, k_min)
        t = sim.time
        return {"t": t, "front_x": front, "column_height": column, "T": t * math.sqrt(2 * G / a), "Z": front / a,
                "tau": t * math.sqrt(G / a), "H": column / (2 * a)}

    closest = math.nan
    try:
        start_hydrostatic(sim, scene, r, corner, a)
        rows, wall, error, signum = sampled_run(sim, sample, steps, every,
                                                f"inclined dam break {angle:g} deg [{s['backend']}]", progress)
        if error is None:
            x = sim.read()["particle_x"].astype(np.float64)
            closest = float(geometry.signed_distance(scene.bodies[0], x).min()) / scene["fluid.spacing"]
    finally:
        sim.close()
    info = {"angle": angle, "particles": sim.fluid_count, "walls": sim.n - sim.fluid_count, "steps": sim.step_count,
            "dt": dt, "wall_s": wall, "min_neighbours": k_min, "column_area_ratio": sim.fluid_count *
            scene["fluid.spacing"] ** 2 / (2 * a * a), "closest_to_wall_dx": closest, "error": error, "signal": signum,
            **dam_break.errors(rows, s)}
    return rows, info


def run_inclined_dam_break(settings=None, out_dir=None, progress=True):
    """The inclined dam break at ANGLE, the box run of dam_break.py (engineering configuration, same resolution and
    end) and (control) the body tank at angle 0: rows of the inclined run, and a summary of all three."""
    s = {**COMMON, **SETTINGS["inclined_dam_break"], **(settings or {})}
    rows, info = run_inclined(s, s["angle"], progress)
    runs = {"inclined": info}
    series = {"inclined": rows}
    if not info["error"]:
        box_rows, box = dam_break.run_dam_break({"resolution": s["resolution"], "t_end": s["t_end"],
                                                 "config": "engineering", "backend": s["backend"]}, None, progress)
        runs["box"] = {k: v for k, v in box.items() if k != "settings"}
        series["box"] = box_rows
        if s["control"]:
            series["body_0deg"], runs["body_0deg"] = run_inclined(s, 0.0, progress)
    for name, data in series.items():  # the front at the end, to compare the runs with each other
        runs[name]["Z_end"] = data[-1]["Z"]
    summary = {"case": "inclined_dam_break", "settings": s, "runs": runs, "error": info["error"],
               "signal": info["signal"], "series": {k: {"T": [r["T"] for r in v], "Z": [r["Z"] for r in v]}
                                                    for k, v in series.items()}}
    if out_dir is not None:
        write_results(rows, summary, out_dir, "inclined_dam_break")
    if info["error"]:
        raise stop(info, out_dir, f"t = {rows[-1]['t']:.4g} s")
    return rows, summary


CASES = {"rotated_tank": run_rotated_tank, "cylindrical_tank": run_cylindrical_tank,
         "forces_at_rest": run_forces_at_rest, "inclined_dam_break": run_inclined_dam_break}


def describe(summary):
    """One line of a case's figures against its targets."""
    case = summary["case"]
    met = ", ".join(f"{k} {'met' if v else 'not met'}" for k, v in summary.get("meets", {}).items())
    if case in ("rotated_tank", "cylindrical_tank"):
        errors = ", ".join(f"{k} {100 * v:+.2f} %" for k, v in summary["pressure_errors_settled"].items())
        return (f"{summary['particles']} particles, {summary['steps']} steps in {summary['wall_s']:.0f} s; settled "
                f"pressure against rho g depth: {errors}; closest to the wall {summary['closest_to_wall_dx']:+.2f} dx; "
                f"targets: {met}")
    if case == "forces_at_rest":
        errors = ", ".join(f"{k} {100 * v:+.2f} %" for k, v in summary["force_errors_settled"].items())
        return f"{summary['particles']} particles; settled forces against their targets: {errors}; targets: {met}"
    return "RMS of Z against Table 2 (T + 0.175): " + ", ".join(
        f"{k} {v['rms_Z_table2']:.3f}" for k, v in summary["runs"].items())


# ---- plots ----

def plot(rows, summary, path):
    """The case's PNG: pressures or forces over time against their targets; the front against the data."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from sphcore.output import atomic_savefig

    case = summary["case"]
    fig, ax = plt.subplots(figsize=(7.5, 4.4), dpi=110)
    t = np.array([r["t"] for r in rows])
    if case in ("rotated_tank", "cylindrical_tank"):
        for k, colour in zip(summary["points"], "bgrm"):
            ax.plot(t, [r[f"{k}_pa"] / 1e3 for r in rows], colour + "-", lw=1,
                    label=f"gauge {k}: settled {100 * summary['pressure_errors_settled'][k]:+.2f} %")
            ax.plot(t, [r[f"{k}_hydrostatic_pa"] / 1e3 for r in rows], colour + "--", lw=0.8)
        ax.set(xlabel="t [s]", ylabel="pressure [kPa]",
               title=f"{case}: gauges (solid) against rho g depth (dashed), {summary['particles']} particles, "
                     f"dx {summary['dx']:g} m")
    elif case == "forces_at_rest":
        e = summary["force_errors_settled"]
        ax.plot(t, [-r["floor_fy"] / r["weight"] for r in rows], label=f"floor -Fy / weight ({100 * e['floor']:+.2f} %)")
        ax.plot(t, [-r["left_fx"] / r["side_hydrostatic"] for r in rows],
                label=f"left wall -Fx / (rho g H^2/2) ({100 * e['left']:+.2f} %)")
        ax.plot(t, [r["right_fx"] / r["side_hydrostatic"] for r in rows],
                label=f"right wall Fx / (rho g H^2/2) ({100 * e['right']:+.2f} %)")
        ax.axhline(1, color="k", lw=0.5)
        for f in (0.99, 1.01, 0.97, 1.03):
            ax.axhline(f, color="k", lw=0.4, ls=":")
        ax.set(xlabel="t [s]", ylabel="force / target", ylim=(0.9, 1.1),
               title=f"forces on a tank of three bodies, {summary['particles']} particles, dx {summary['dx']:g} m")
    else:
        for name, marker in zip(dam_break.FRONT_SERIES, "os^v"):
            T_exp, Z_exp, _ = dam_break.read_series(name)
            ax.plot(T_exp, Z_exp, marker, ms=4, mfc="none", label=dam_break.FRONT_SERIES[name][1])
        shift = dam_break.GATE_SHIFT
        for (name, data), style in zip(summary["series"].items(), ("k-", "b--", "g:")):
            rms = summary["runs"][name]["rms_Z_table2"]
            ax.plot(np.array(data["T"]) + shift, data["Z"], style, label=f"sphcore {name} (T + {shift:g}), RMS {rms:.3f}")
        end = max(data["T"][-1] for data in summary["series"].values()) + shift
        ax.set(xlabel="T = t sqrt(2g/a)", ylabel="Z = front / a (tank frame)", xlim=(0, end + 0.3),
               ylim=(1, dam_break.TANK_LENGTH),
               title=f"Martin & Moyce in a tank rotated {summary['settings']['angle']:g} deg, "
                     f"{summary['settings']['resolution']} across a")
    ax.title.set_fontsize(9)
    ax.legend(fontsize=7)
    fig.tight_layout()
    atomic_savefig(fig, path)
    plt.close(fig)
    return path
