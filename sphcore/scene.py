"""Scenes: TOML files over documented defaults. Every key has a unit and a range.

A scene file names only what differs from `SCHEMA`'s defaults. Unknown keys, wrong types and
out-of-range values are rejected with a `SceneError` naming the file and the key. `sphcore
keys` prints the table below.
"""
import copy
import dataclasses
import json
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

from sphcore import geometry
from sphcore.decomposition import launched_ranks
from sphcore.errors import SceneError  # noqa: F401 (sphcore.scene.SceneError)
from sphcore.gauges import check_scene as check_gauge_places
from sphcore.gauges import check_shape as check_gauges
from sphcore.params import CELL_PADDING, KERNELS, MAX_CELLS, MAX_OBSTACLES, Spec, fold_parameters, lattice_mass
from sphcore.paths import SCENE_DIR

DENSITY_DIFFUSIONS = ("none", "molteni", "fourtakas")  # physics.density_diffusion -> spec constant DENSITY_DIFFUSION


def shipped_scenes():
    """Names of the scenes that come with sphcore (`sphcore run NAME`, `Scene.load(NAME)`)."""
    return sorted(p.stem for p in SCENE_DIR.glob("*.toml"))


def scene_path(name):
    """A path as given, else a scene shipped in scenes/ (`dam_break_2d` or `dam_break_2d.toml`)."""
    path = Path(name)
    if path.exists() or path.suffix == ".toml" and path.parent != Path("."):
        return path
    shipped = SCENE_DIR / (path.name if path.suffix else f"{path.name}.toml")
    return shipped if shipped.exists() else path


MAX_SCENE_BYTES = 2**20  # a scene file (or a run's scene.json) larger than this is not one


def read_limited(path, limit=MAX_SCENE_BYTES):
    """The text (UTF-8, a byte-order mark allowed) of file `path`, refused past `limit` bytes
    (`sphcore run /dev/zero` would read until memory runs out)."""
    with open(path, "rb") as f:
        data = f.read(limit + 1)
    if len(data) > limit:
        raise SceneError(f"{path}: larger than {limit // 1024} KiB: not a scene file")
    return data.decode("utf-8-sig")


def stable_dt(scene, max_speed=0.0):
    """Largest stable time step [s] and the bound that sets it.

    CFL: 0.25 h / (c + |v|max), c = sqrt(k); viscous: 0.125 h^2 rho_0 / mu (mu: Scene.shear_viscosity); body force:
    0.25 sqrt(h / |g|) (Monaghan 1992; Morris et al. 1997). Terms switched off in physics.* do
    not bound it.
    """
    h = scene.h
    bounds = {"CFL": 0.25 * h / (math.sqrt(scene["fluid.stiffness"]) + max_speed)}
    if scene["physics.pressure_solver"] == "dfsph":  # incompressible: the CFL number on the particle speed alone
        bounds = {"CFL": scene["time.cfl_number"] * scene["fluid.spacing"] / max_speed if max_speed > 0 else math.inf}
    mu = scene.shear_viscosity
    if mu > 0 and scene["physics.viscosity"]:
        bounds["viscous"] = 0.125 * h * h * scene["fluid.rest_density"] / mu
    g = math.sqrt(sum(c * c for c in scene["forces.gravity"]))
    if g > 0 and scene["physics.gravity"]:
        bounds["force"] = 0.25 * math.sqrt(h / g)
    name = min(bounds, key=bounds.get)
    return bounds[name], name


# spec_for: the most list slots (4 bytes each) a backend gets for the state equation: 1 GiB of host memory on
# numba, a 4 GiB buffer on Vulkan (its largest storage buffer)
LIST_WORDS = {"numba": 1 << 28, "vulkan": (1 << 30) - 1}
# DFSPH's stored pair gradients (spec.GRADIENTS: 16 bytes a list slot) where they fit in this many slots: numba
# only, whose sweeps were bound by computing each pair again (9,600 particles, 2 cores: 11.8 -> 10.3 ms a
# step); on the H200 reading them was slower than computing them (1 M particles: 4.17 -> 4.37 ms)
GRADIENT_SLOTS = {"numba": 1 << 26}

DEFAULT_MODEL = "engineering"  # physics.model of a scene that names none


@dataclass(frozen=True)
class Key:
    default: object
    unit: str
    low: float
    high: float
    doc: str
    kind: str = "float"  # float | int | vec | str | bool | blocks | boxes (blocks, or none) | dt (a float or "auto") | one of "a|b|c"


# physics.model -> the keys it sets, where the scene does not give them (SCHEMA's defaults are DEFAULT_MODEL's).
# Every model sets the same keys, so that a scene names its model whole.
PRESETS = {
    # Mueller et al. 2003 (the seeds' model)
    "graphics": {"physics.pressure_solver": "state_equation", "physics.kernel": "mueller",
                 "fluid.smoothing_ratio": 2.0, "physics.density": "summation", "physics.density_diffusion": "none",
                 "fluid.density_diffusion": 0.1, "physics.viscosity_model": "laminar", "fluid.alpha": 0.02,
                 "fluid.relaxation": 1.0, "time.integrator": "symplectic_euler", "time.dt": 1e-4},
    # weakly compressible SPH as TrixiParticles' examples/fluid/dam_break_2d.jl: Wendland 1995's C2 with smoothing
    # length 2 dx (support radius 4 dx), Molteni & Colagrossi 2009, Monaghan 1992 (alpha 0.02 on the smoothing
    # length), velocity Verlet; sphcore validate's "engineering" configuration (docs/models/index.md)
    "engineering": {"physics.pressure_solver": "state_equation", "physics.kernel": "wendland_c2",
                    "fluid.smoothing_ratio": 4.0, "physics.density": "continuity", "physics.density_diffusion": "molteni",
                    "fluid.density_diffusion": 0.1, "physics.viscosity_model": "artificial", "fluid.alpha": 0.01,
                    "fluid.relaxation": 1.0, "time.integrator": "verlet", "time.dt": "adaptive"},
    # Bender & Koschier 2015, 2017 with the kernel and relaxation with which a tank comes to rest
    # (docs/models/dfsph.md; sphcore validate's "dfsph_wendland"); dt "auto": the largest step from the viscous
    # bound and the CFL step at the free-fall speed, not time.dt's fixed 1e-4 s
    "dfsph": {"physics.pressure_solver": "dfsph", "physics.kernel": "wendland_c2", "fluid.smoothing_ratio": 2.0,
              "physics.density": "summation", "physics.density_diffusion": "none", "fluid.density_diffusion": 0.1,
              "physics.viscosity_model": "laminar", "fluid.alpha": 0.02, "fluid.relaxation": 0.8,
              "time.integrator": "symplectic_euler", "time.dt": "auto"},
}

SCHEMA = {
    "name": Key("scene", "", 0, 0, "name used for output files", "str"),
    "physics": {
        "model": Key(DEFAULT_MODEL, "", 0, 0, "the model: the values of the keys it sets (each lists them) where the "
                     "scene does not give them. graphics: Mueller et al. 2003's kernels on 2 dx, summation density, "
                     "laminar viscosity, symplectic Euler, dt 1e-4 s (fast; blows up in dam breaks); engineering: "
                     "Wendland 1995's C2 on 4 dx, continuity density with Molteni & Colagrossi 2009's diffusion, "
                     "Monaghan 1992's artificial viscosity, Verlet, adaptive dt (TrixiParticles' dam_break_2d.jl); "
                     "dfsph: DFSPH (Bender & Koschier 2015, 2017), Wendland C2 on 2 dx, summation density, laminar "
                     'viscosity, symplectic Euler, omega 0.8, dt from time.cfl_number up to the "auto" step',
                     "graphics|engineering|dfsph"),
        "dimension": Key(2, "-", 2, 3, "2 or 3; every vector in the scene has this many components", "int"),
        "neighbour_search": Key("grid", "", 0, 0, "grid (cells of size h, HistoPyramid counting sort) or "
                                "all_pairs (O(n^2), no grid)", "grid|all_pairs"),
        "equation_of_state": Key("linear", "", 0, 0, "linear: p = k (rho - rho_0) (seed 1); tait: "
                                 "p = B ((rho/rho_0)^7 - 1), B = rho_0 k / 7 (seed 2)", "linear|tait"),
        "viscosity": Key(True, "", 0, 0, "the viscosity term (physics.viscosity_model: Mueller's, coefficient "
                         "fluid.viscosity, or Monaghan's artificial one, coefficient fluid.alpha)", "bool"),
        "surface_tension": Key(False, "", 0, 0, "cohesion of Becker & Teschner 2007 (coefficient "
                               "fluid.cohesion)", "bool"),
        "gravity": Key(True, "", 0, 0, "the gravity term (vector forces.gravity)", "bool"),
        "precision": Key("float32", "", 0, 0, "float32, or float64 particle buffers and arithmetic (the "
                         "Vulkan device must support shaderFloat64)", "float32|float64"),
        "kernel": Key("wendland_c2", "", 0, 0, "mueller: poly6 values, spiky gradients, viscosity Laplacian (Mueller et "
                      "al. 2003); wendland_c2: Wendland C2 for values and gradients, Morris et al. 1997's "
                      "Laplacian; support radius h for both", "mueller|wendland_c2"),
        "density": Key("continuity", "", 0, 0, "summation: rho_i = sum_j m W_ij each step, pressure clamped at 0; "
                       "continuity: d rho/dt = sum_j m (v_i - v_j) . grad W_ij integrated, starting hydrostatic, "
                       "negative pressures kept", "summation|continuity"),
        "density_diffusion": Key("molteni", "", 0, 0, "delta-SPH term of the continuity density (coefficient "
                                 "fluid.density_diffusion): molteni (Molteni & Colagrossi 2009) or fourtakas "
                                 "(Fourtakas et al. 2019: its hydrostatic part removed)", "none|molteni|fourtakas"),
        "viscosity_model": Key("artificial", "", 0, 0, "laminar: mu sum_j m (v_j - v_i) L_ij / (rho_i rho_j) (Mueller et al. "
                               "2003), coefficient fluid.viscosity; artificial: Monaghan 1992's Pi_ij = -alpha c h "
                               "(v_ij . r_ij) / (rho_ij (r^2 + 0.01 h^2)) for approaching pairs, coefficient fluid.alpha",
                               "laminar|artificial"),
        "pressure_solver": Key("state_equation", "", 0, 0, "state_equation: the pressure from the density by "
                               "physics.equation_of_state (weakly compressible); dfsph: divergence-free SPH (Bender & "
                               "Koschier 2015, 2017), a divergence-free and a constant-density solve each step to "
                               "fluid.max_divergence_error and fluid.max_density_error, dt from time.cfl_number on the "
                               "particle speed", "state_equation|dfsph"),
        "list_skin": Key(0.0, "h", 0.0, 1.0, "the state equation's neighbour lists reused between builds: a build "
                         "sorts the particles and lists every pair within (1 + list_skin) h, and the lists serve until a "
                         "particle has moved list_skin h / 2.05 (rounded to 0.001 h); 0: a sort and a list every step"),
        "shifting": Key("none", "", 0, 0, "particle shifting: lind moves each particle down its concentration "
                        "gradient, dr_i = -D grad C_i, D = A h_s |v_i| dt (Lind et al. 2012, Skillen et al. 2013; "
                        "coefficient A = fluid.shifting), not at the free surface (DualSPHysics' threshold); state "
                        "equation only", "none|lind"),
    },
    "domain": {
        "box_min": Key([0.0, 0.0], "m", -1e3, 1e3, "lower corner of the walls (open: origin of the hashed grid)", "vec"),
        "box_max": Key([1.0, 1.0], "m", -1e3, 1e3, "upper corner of the walls (open: the hash period ends here)", "vec"),
        "boundary": Key("walls", "", 0, 0, "walls: a closed box; open: unbounded, grid cells hashed modulo "
                        "the box (seed 2)", "walls|open"),
        "obstacles": Key([], "m", -1e3, 1e3, "solid boxes inside the domain that the fluid flows around (images "
                         f"across their faces, as at the walls): [{{min = [...], max = [...]}}], at most {MAX_OBSTACLES}",
                         "boxes"),
        "wall_model": Key("free_slip", "", 0, 0, "velocity of the walls' and obstacles' mirror images: free_slip "
                          "reverses its normal component (no shear), no_slip all of it (the fluid is dragged); "
                          "the bodies' wall particles: no shear, or the fluid's velocity reversed (Adami et al. 2012)",
                          "free_slip|no_slip"),
    },
    "fluid": {
        "blocks": Key([{"min": [0.1, 0.1], "max": [0.4, 0.4]}], "m", -1e3, 1e3,
                      "boxes filled with particles on a square (cubic) lattice: [{min = [...], max = [...]}]",
                      "blocks"),
        "spacing": Key(0.01, "m", 1e-5, 1.0, "particle spacing dx of the initial lattice"),
        "smoothing_ratio": Key(4.0, "-", 1.5, 6.0, "support radius h / spacing"),
        "rest_density": Key(1000.0, "kg/m^3", 1.0, 1e5, "rest density rho_0"),
        "stiffness": Key(400.0, "m^2/s^2", 1.0, 1e8,
                         "k = c^2 for a speed of sound c (about 10x the fastest flow); linear and Tait alike"),
        "viscosity": Key(1.0, "Pa s", 0.0, 1e5, "dynamic viscosity mu of Mueller's viscosity term"),
        "cohesion": Key(0.0, "m^dim/s^2", 0.0, 1e6, "kappa of the cohesion force -kappa sum_j W(r_ij) (x_i - x_j)"),
        "alpha": Key(0.01, "-", 0.0, 10.0, 'alpha of physics.viscosity_model = "artificial" (Monaghan 1992), with '
                     "c = sqrt(stiffness); its shear viscosity is mu = alpha rho_0 c h / (2 dim + 4)"),
        "shifting": Key(2.0, "-", 0.0, 10.0, 'A of physics.shifting = "lind": D = A h_s |v_i| dt, h_s = h / 2 '
                        "(DualSPHysics' ShiftCoef, -2 there with the sign)"),
        "density_diffusion": Key(0.1, "-", 0.0, 1.0, "delta of physics.density_diffusion: D_i = delta h_s c_0 "
                                 "sum_j psi_ij . grad W_ij V_j, h_s = h / 2, c_0 = sqrt(stiffness)"),
        "max_density_error": Key(0.001, "-", 1e-6, 0.1, 'physics.pressure_solver = "dfsph": the constant-density solve '
                                 "stops when the mean compression max(rho*/rho_0 - 1, 0) is at most this (0.001: 0.1 %)"),
        "max_divergence_error": Key(0.001, "-", 1e-6, 0.1, 'physics.pressure_solver = "dfsph": the divergence-free solve '
                                    "stops when the mean compression rate times dt is at most this"),
        "relaxation": Key(1.0, "-", 0.05, 1.0, 'physics.pressure_solver = "dfsph": omega, the share of each Jacobi '
                          "update the solves apply (1: Bender & Koschier's and SPlisHSPlasH's). Below 1 a solve takes "
                          "more iterations and settles where 1 oscillates; a support of 4 dx needs about 0.5"),
        "max_iterations": Key(100, "-", 2, 1000, 'physics.pressure_solver = "dfsph": updates per solve and step at '
                              "most (recorded on the device); a solve that reaches it unconverged is reported", "int"),
        "max_neighbours": Key(0, "-", 0, 1024, 'physics.pressure_solver = "dfsph": slots of each particle\'s neighbour '
                              "list (its neighbours and their wall images within h, which the solves' sweeps walk); 0: "
                              "twice the particles of a ball of radius h at the spacing. A particle with more stops the "
                              "run, naming the step", "int"),
    },
    "forces": {
        "gravity": Key([0.0, -9.81], "m/s^2", -1e4, 1e4, "gravitational acceleration", "vec"),
    },
    "walls": {
        "restitution": Key(0.3, "-", 0.0, 1.0, "fraction of the normal speed kept when a particle hits a wall"),
    },
    "time": {
        "dt": Key("adaptive", "s", 1e-8, 1.0, 'time step, or "auto": dt_fraction times the stability bound '
                  '(CFL, viscous, body force; see stable_dt), or "adaptive": that bound computed on the device '
                  "every step from the fastest particle and the largest acceleration", "dt"),
        "dt_fraction": Key(1.0, "-", 0.01, 10.0, 'fraction of the stability bound taken by dt = "auto" or "adaptive"'),
        "integrator": Key("verlet", "", 0, 0, "symplectic_euler: v += dt a, x += dt v (first order); verlet: "
                          "kick-drift-kick leapfrog, one force evaluation per step (second order)",
                          "symplectic_euler|verlet"),
        "cfl_number": Key(0.4, "-", 0.01, 1.0, 'physics.pressure_solver = "dfsph": dt = min(the largest step, cfl_number '
                          "fluid.spacing / |v|max) on the device each step (no sound speed)"),
        "end": Key(0.0, "s", 0.0, 1e9, "simulated time at which the run ends, in place of time.steps (0: not given; "
                   "time.steps counts the run)"),
        "output_interval": Key(0.0, "s", 0.0, 1e9, "simulated time between snapshots, in place of time.output_every "
                               "(0: not given; time.output_every counts them)"),
        "steps": Key(5000, "steps", 0, 1e9, "steps to run unless --steps is given (0 where time.end ends the run)", "int"),
        "output_every": Key(250, "steps", 0, 1e9, "steps between snapshots (0 where time.output_interval sets them)",
                            "int"),
        "checkpoint_every": Key(1000, "steps", 1, 1e9, "steps between checkpoints (what `sphcore run --resume` "
                                "continues from)", "int"),
    },
    "bodies": Key([], "m", -1e3, 1e3, "solid bodies from meshes (3D) and polygons (2D), walled by wall particles: "
                  '[[bodies]] tables with name (unique), mesh = "file.stl" (3D: a closed STL, OBJ or PLY surface, its path '
                  "relative to the scene file) or polygon = [[x, y], ...] (2D: a simple closed polygon, its vertices in "
                  "order), scale (default 1), rotate (degrees about x, then y, then z, about the origin; 2D: one angle; "
                  "default 0), translate (m, default 0; scale, then rotate, then translate) and fluid (outside: an "
                  "obstacle in the flow, the default; inside: a container holding the fluid). Fluid blocks are clipped "
                  "to dx / 2 off every body (docs/scenes.md, Bodies)", "bodies"),
    "gauges": Key([], "", 0, 0, "measurements taken on the device every `interval` seconds and written to "
                  "RUN/gauges/NAME.csv: [[gauges]] tables of name, quantity (pressure|velocity|density|height|force|"
                  "moment), at (a point; height: the foot of a vertical line), body and about (force, moment), "
                  "interval [s] (docs/scenes.md: Gauges)", "gauges"),
}

MAX_PARTICLES = 50_000_000  # a process holds at most this many (under mpiexec: a rank; in all, launched_ranks times it)
# the keys a folded parameter comes from, first the one to change when it overflows float32
_FOLDED_FROM = {
    "cohesion_coef": ("fluid.cohesion", "fluid.spacing", "fluid.smoothing_ratio"),
    "viscosity_coef": ("fluid.viscosity", "fluid.spacing", "fluid.smoothing_ratio"),
    "stiffness": ("fluid.stiffness", "fluid.rest_density"),
    "diffusion_coef": ("fluid.density_diffusion", "fluid.stiffness", "fluid.spacing", "fluid.smoothing_ratio"),
}


def _shown(value, width=60):
    """repr(value), cut to `width` characters (a 400-digit integer makes no message clearer)."""
    text = repr(value)
    return text if len(text) <= width else f"{text[:width - 3]}..."


def _check(where, key, value):
    """Validate one value against its Key; return it in canonical form."""
    if key.kind == "str":  # the name: output files are named after it, in the output folder
        if not isinstance(value, str) or not value:
            raise SceneError(f"{where}: expected a non-empty string, got {_shown(value)}")
        if value.startswith(".") or any(c in value for c in "/\\") or not value.isprintable():
            raise SceneError(f"{where} = {_shown(value)}: must be a file name (no /, \\, leading dot or "
                             "control characters)")
        return value
    if "|" in key.kind:
        if value not in key.kind.split("|"):
            raise SceneError(f"{where} = {_shown(value)}: choose one of {', '.join(map(repr, key.kind.split('|')))}")
        return value
    if key.kind == "gauges":
        return check_gauges(where, value)
    if key.kind == "dt" and value in ("auto", "adaptive"):
        return value
    if key.kind == "bool":
        if not isinstance(value, bool):
            raise SceneError(f"{where}: expected true or false, got {_shown(value)}")
        return value
    if key.kind == "int":
        if isinstance(value, bool) or not isinstance(value, int):
            raise SceneError(f"{where}: expected an integer ({key.unit}), got {_shown(value)}")
    elif key.kind in ("float", "dt"):
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            expected = 'a number, "auto" or "adaptive"' if key.kind == "dt" else "a number"
            raise SceneError(f"{where}: expected {expected} ({key.unit}), got {_shown(value)}")
        if isinstance(value, int) and not key.low <= value <= key.high:  # before float() overflows
            raise SceneError(f"{where} = {_shown(value)}: must be within [{key.low:g}, {key.high:g}] {key.unit}")
        value = float(value)
    elif key.kind == "vec":
        if (not isinstance(value, list) or len(value) not in (2, 3)
                or any(isinstance(v, bool) or not isinstance(v, (int, float)) for v in value)):
            raise SceneError(f"{where}: expected [x, y] or [x, y, z] ({key.unit}), got {_shown(value)}")
        return [_check(f"{where}[{i}]", Key(0, key.unit, key.low, key.high, ""), v) for i, v in enumerate(value)]
    elif key.kind in ("blocks", "boxes"):
        if not isinstance(value, list) or (not value and key.kind == "blocks"):
            raise SceneError(f"{where}: expected a list of {{min = [...], max = [...]}} tables, got {_shown(value)}")
        blocks = []
        corner = Key(0, key.unit, key.low, key.high, "", "vec")
        for i, block in enumerate(value):
            if not isinstance(block, dict) or set(block) != {"min", "max"}:
                raise SceneError(f"{where}[{i}]: expected a table with exactly the keys min and max, got {_shown(block)}")
            lo, hi = _check(f"{where}[{i}].min", corner, block["min"]), _check(f"{where}[{i}].max", corner, block["max"])
            if len(lo) != len(hi) or not all(a < b for a, b in zip(lo, hi)):
                raise SceneError(f"{where}[{i}]: min {lo} must be below max {hi} on every axis")
            blocks.append({"min": lo, "max": hi})
        return blocks
    elif key.kind == "bodies":
        return _check_bodies(where, key, value)
    if not key.low <= value <= key.high:  # NaN is never within
        raise SceneError(f"{where} = {_shown(value)}: must be within [{key.low:g}, {key.high:g}] {key.unit}")
    return value


# the keys of one [[bodies]] table (SCHEMA's "bodies" describes them); rotate and translate default to zeros of
# the scene's dimension (Scene.from_dict)
BODY_KEYS = {
    "name": Key("", "", 0, 0, "", "str"),
    "scale": Key(1.0, "-", 1e-6, 1e6, ""),
    "angle": Key(0.0, "deg", -360.0, 360.0, ""),
    "fluid": Key("outside", "", 0, 0, "", "outside|inside"),
}


def _check_bodies(where, key, value):
    """The [[bodies]] tables, each checked key by key (what needs the dimension or the geometry waits for
    Scene._check_bodies); a message names the body, `bodies[1] ("tank")`."""
    if not isinstance(value, list):
        raise SceneError(f"{where}: expected a list of tables ([[bodies]] in a scene file), got {_shown(value)}")
    bodies, names = [], {}
    for i, body in enumerate(value):
        at = geometry.where(i, body).replace("bodies", where, 1)
        if not isinstance(body, dict):
            raise SceneError(f"{at}: expected a table, got {_shown(body)}")
        unknown = sorted(set(body) - {"name", "mesh", "polygon", "scale", "rotate", "translate", "fluid"}, key=str)
        if unknown:
            raise SceneError(f"{at}: unknown key {_shown(unknown[0])} (known: fluid, mesh, name, polygon, rotate, scale, "
                             "translate)")
        if "name" not in body:
            raise SceneError(f"{at}: give it a name (name = \"...\")")
        out = {"name": _check(f"{at}.name", BODY_KEYS["name"], body["name"])}
        if out["name"] in names:
            raise SceneError(f"{at}: the name is also bodies[{names[out['name']]}]'s; give each body its own")
        names[out["name"]] = i
        given = [k for k in ("mesh", "polygon") if k in body]
        if len(given) != 1:
            raise SceneError(f"{at}: give exactly one of mesh (3D) and polygon (2D), not "
                             f"{'both' if given else 'neither'}")
        if "mesh" in body:
            if not isinstance(body["mesh"], str) or not body["mesh"] or not body["mesh"].isprintable():
                raise SceneError(f"{at}.mesh: expected a file name, got {_shown(body['mesh'])}")
            out["mesh"] = body["mesh"]
        else:
            polygon = body["polygon"]
            if not isinstance(polygon, list) or len(polygon) < 3:
                raise SceneError(f"{at}.polygon: expected at least 3 vertices [[x, y], ...], got {_shown(polygon)}")
            vertex = Key(0, key.unit, key.low, key.high, "", "vec")
            out["polygon"] = [_check(f"{at}.polygon[{k}]", vertex, v) for k, v in enumerate(polygon)]
            if any(len(v) != 2 for v in out["polygon"]):
                raise SceneError(f"{at}.polygon: every vertex is [x, y] (a polygon is 2D)")
        out["scale"] = _check(f"{at}.scale", BODY_KEYS["scale"], body.get("scale", 1.0))
        if "rotate" in body:
            angles = body["rotate"]
            out["rotate"] = ([_check(f"{at}.rotate[{k}]", BODY_KEYS["angle"], a) for k, a in enumerate(angles)]
                             if isinstance(angles, list) else _check(f"{at}.rotate", BODY_KEYS["angle"], angles))
        if "translate" in body:
            out["translate"] = _check(f"{at}.translate", Key(0, key.unit, key.low, key.high, "", "vec"), body["translate"])
        out["fluid"] = _check(f"{at}.fluid", BODY_KEYS["fluid"], body.get("fluid", "outside"))
        bodies.append(out)
    return bodies


def _merge(where, schema, given, preset):
    if not isinstance(given, dict):
        raise SceneError(f"{where or 'scene'}: expected a table, got {_shown(given)}")
    unknown = sorted(set(given) - set(schema), key=str)
    if unknown:
        raise SceneError(f"{where or 'scene'}: unknown key {_shown(unknown[0])} (known: {', '.join(sorted(schema))})")
    out = {}
    for name, key in schema.items():
        path = f"{where}.{name}" if where else name
        if isinstance(key, dict):
            out[name] = _merge(path, key, given.get(name, {}), preset)
        else:
            out[name] = _check(path, key, given[name]) if name in given else preset.get(path, key.default)
    return out


def _resolve_time(config, given):
    """time.end against time.steps and time.output_interval against time.output_every: at most one of each
    pair given (0 is "not given"); where the time in seconds is given, the step count is 0 in `config`."""
    time = config["time"]
    for seconds, steps, what in (("end", "steps", "the run's length"), ("output_interval", "output_every",
                                                                         "the snapshots' spacing")):
        if time[seconds] > 0 and given.get(steps, 0) > 0:
            raise SceneError(f"time.{seconds} = {time[seconds]:g} s and time.{steps} = {given[steps]} both set "
                             f"{what}: give one of them")
        if time[seconds] > 0:
            time[steps] = 0
        elif time[steps] == 0:
            raise SceneError(f"time.{steps} = 0: give time.{steps} > 0 or time.{seconds} > 0 s")


def _resolve_bodies(config, source):
    """Each body's rotate and translate defaulted to zeros of the scene's dimension, and its mesh path made
    absolute (scene.json, which resume reads, must find it): relative to the scene file `source`, or to the
    working folder for a scene from a dict (`source` "<dict>")."""
    dim = config["physics"]["dimension"]
    base = Path.cwd() if source.startswith("<") else Path(source).parent
    for body in config["bodies"]:
        body.setdefault("rotate", 0.0 if dim == 2 else [0.0, 0.0, 0.0])
        body.setdefault("translate", [0.0] * dim)
        if "mesh" in body:
            body["mesh"] = os.path.abspath(base / Path(body["mesh"]).expanduser())


@dataclass
class Scene:
    """A validated scene: `config` holds every key, defaults filled in; `scene["fluid.spacing"]`
    reads one. Make one with `Scene.load(path_or_name)` or `Scene.from_dict({...})` (a dict shaped
    like the TOML file: only what differs from the defaults; `sphcore keys` lists them).

    >>> import sphcore
    >>> scene = sphcore.Scene.from_dict({"fluid": {"spacing": 0.02}})
    >>> scene["fluid.spacing"], scene["physics.kernel"]  # given, and the default model's (engineering)
    (0.02, 'wendland_c2')
    >>> sphcore.Scene.from_dict({"physics": {"model": "graphics"}})["physics.kernel"]  # physics.model's
    'mueller'
    >>> scene.dim, len(scene.initial_positions())  # the default block, 0.3 m square, at 2 cm
    (2, 225)
    >>> sphcore.Scene.load("dam_break_2d")["fluid.spacing"]  # a shipped scene
    0.01
    """
    config: dict
    source: str = "<defaults>"
    from_model: dict = dataclasses.field(default_factory=dict, compare=False, repr=False)  # keys physics.model set -> which
    _made: dict = dataclasses.field(default_factory=dict, compare=False, repr=False)  # the bodies' geometry (_geometry)

    def __getstate__(self):  # a pickled scene (a sweep's task) leaves its loaded meshes behind: made again
        return {**self.__dict__, "_made": {}}

    @classmethod
    def from_dict(cls, data, source="<dict>"):
        """The scene of `data` (nested dicts, as a TOML file parses), checked: SceneError names a bad key."""
        physics = data.get("physics") if isinstance(data, dict) else None
        named = isinstance(physics, dict) and "model" in physics
        model = _check("physics.model", SCHEMA["physics"]["model"], physics["model"]) if named else DEFAULT_MODEL
        config = _merge("", SCHEMA, data, PRESETS[model])
        if config["physics"]["dimension"] == 3:  # vectors left at their 2D defaults gain a z component
            for table, name, z in (("domain", "box_min", 0.0), ("domain", "box_max", 1.0), ("forces", "gravity", 0.0)):
                if name not in data.get(table, {}):
                    config[table][name] = config[table][name] + [z]
        _resolve_time(config, data.get("time", {}))
        _resolve_bodies(config, source)
        by = f'physics.model = "{model}"' + ("" if named else ", the default")
        given = {f"{table}.{key}" for table, keys in data.items() if isinstance(keys, dict) for key in keys}
        scene = cls(config, source, {k: by for k in PRESETS[model] if k not in given})
        scene._check_models()
        scene._check_geometry()
        return scene

    @classmethod
    def load(cls, path):
        """The scene in TOML file `path`, or the shipped scene of that name (`Scene.load("dam_break_2d")`)."""
        given, path = path, scene_path(path)
        if Path(path).suffix.lower() in geometry.MESH_SUFFIXES:
            raise SceneError(f"{path}: a mesh, not a scene: name it in a scene's [[bodies]] (mesh = \"{Path(path).name}\"; "
                             "docs/scenes.md, Bodies)")
        try:
            data = tomllib.loads(read_limited(path))  # a byte-order mark is allowed
        except FileNotFoundError:
            if Path(given).parent == Path(".") and Path(given).suffix in ("", ".toml"):
                raise SceneError(f"{_shown(str(given))}: no such scene file, and no shipped scene of that name (shipped: "
                                 f"{', '.join(shipped_scenes())})") from None
            raise SceneError(f"{path}: no such scene file") from None
        except OSError as e:  # a folder, no permission
            raise SceneError(f"{path}: cannot read ({e.strerror})") from None
        except UnicodeDecodeError as e:
            raise SceneError(f"{path}: not UTF-8 text ({e.reason} at byte {e.start})") from None
        except tomllib.TOMLDecodeError as e:
            raise SceneError(f"{path}: malformed TOML: {e}") from None
        except RecursionError:
            raise SceneError(f"{path}: malformed TOML: arrays or tables nested too deeply") from None
        try:
            return cls.from_dict(data, str(path))
        except SceneError as e:
            raise SceneError(f"{path}: {e}") from None

    def validated(self):
        """A copy of this scene checked again, as from_dict checks a new one (SceneError names the key):
        what sphcore.run and Simulation use, so that a change made to `config` after the scene was
        loaded (a name with a "/" in it: files outside the output folder), or a Scene built without
        from_dict, is checked before anything runs or is written, and a change made later does not
        reach the run."""
        try:
            return type(self).from_dict(copy.deepcopy(self.config), self.source)
        except SceneError as e:
            raise SceneError(f"{self.source}: {e} (the scene's config was changed after it was checked)") from None

    def __getitem__(self, dotted):
        node = self.config
        for part in dotted.split("."):
            node = node[part]
        return node

    @property
    def dim(self):
        """2 or 3: physics.dimension."""
        return self["physics.dimension"]

    @property
    def dt(self):
        """The time step [s]: time.dt, or time.dt_fraction of the stability bound where it is "auto"."""
        if self.dfsph:  # the estimate: the largest step, or the CFL number's at the free-fall speed
            speed, largest = self.speed_estimate(), self._folded_dt()
            return min(largest, self["time.cfl_number"] * self["fluid.spacing"] / speed) if speed > 0 else largest
        if self["time.dt"] in ("auto", "adaptive"):  # adaptive: the estimate; the device sets each step's
            return self["time.dt_fraction"] * stable_dt(self, self.speed_estimate())[0]
        return self["time.dt"]

    @property
    def end_time(self):
        """Simulated time [s] at which the run ends (time.end), or None where time.steps counts the run."""
        return self["time.end"] if self["time.end"] > 0 else None

    @property
    def output_interval(self):
        """Simulated time [s] between snapshots (time.output_interval), or None where time.output_every
        counts them in steps."""
        return self["time.output_interval"] if self["time.output_interval"] > 0 else None

    @property
    def shear_viscosity(self):
        """mu [Pa s]: fluid.viscosity, or for the artificial viscosity its shear viscosity alpha rho_0 c h
        / (2 dim + 4) (Monaghan 2005, sec. 4.6)."""
        if self["physics.viscosity_model"] == "artificial":
            return (self["fluid.alpha"] * self["fluid.rest_density"] * math.sqrt(self["fluid.stiffness"]) * self.h
                    / (2 * self.dim + 4))
        return self["fluid.viscosity"]

    @property
    def adaptive_dt(self):
        """Whether each step's dt is computed on the device (time.dt = "adaptive")."""
        return self["time.dt"] == "adaptive" or self.dfsph

    @property
    def dfsph(self):
        """Whether the pressure comes from the DFSPH solver (physics.pressure_solver = "dfsph"): then each
        step's dt is the device's (CFL on the particle speed), time.dt (a number) its largest."""
        return self["physics.pressure_solver"] == "dfsph"

    def _folded_dt(self):
        """P.dt: the time step, or where it is adaptive the largest one, dt_fraction times the viscous
        bound (1 s without viscosity) and for DFSPH times the CFL step at the free-fall speed: the
        state-dependent bounds are the device's (choose_dt.comp)."""
        if not self.adaptive_dt or self.dfsph and self["time.dt"] not in ("auto", "adaptive"):
            return self["time.dt"] if self.dfsph else self.dt
        mu = self.shear_viscosity
        largest = 1.0
        if mu > 0 and self["physics.viscosity"]:
            largest = self["time.dt_fraction"] * 0.125 * self.h ** 2 * self["fluid.rest_density"] / mu
        speed = self.speed_estimate()
        if self.dfsph and speed > 0:  # DFSPH: the CFL step at the fastest flow to expect (free fall over the
            # fluid's height); a larger first step, while the fluid is still slow, spoilt the 3D dam break's
            # front at 1 M particles (RMS of Z 0.33 against 0.11: README)
            largest = min(largest, self["time.dt_fraction"] * self["time.cfl_number"] * self["fluid.spacing"] / speed)
        return largest

    def speed_estimate(self):
        """The fastest flow to expect [m/s]: free fall from the top of the fluid to the floor,
        sqrt(2 |g| height) (0 without gravity)."""
        g = self["forces.gravity"]
        g_norm = math.sqrt(sum(c * c for c in g)) if self["physics.gravity"] else 0.0
        if g_norm == 0:
            return 0.0
        down = [c / g_norm for c in g]
        lo, hi = self["domain.box_min"], self["domain.box_max"]
        floor = sum(d * (h if d > 0 else l) for d, l, h in zip(down, lo, hi))  # the wall gravity points at
        top = min(sum(d * (b["min"][a] if d > 0 else b["max"][a]) for a, d in enumerate(down))
                  for b in self["fluid.blocks"])
        return math.sqrt(2.0 * g_norm * max(floor - top, 0.0))

    @property
    def h(self):
        """The kernels' support radius [m]: fluid.spacing times fluid.smoothing_ratio."""
        return self["fluid.spacing"] * self["fluid.smoothing_ratio"]

    def _check_models(self):
        """Combinations of physics.* that have no meaning: one SceneError naming the keys on both sides, and
        the model that set any of them."""
        if self.dfsph:
            conflicts = [(key, why) for key, value, why in (
                ("physics.density", "continuity", "DFSPH's densities are summed each step"),
                ("time.integrator", "verlet", "the solve corrects the symplectic Euler step's velocity"))
                if self[key] == value]
            if conflicts:
                self._refuse("physics.pressure_solver", [k for k, _ in conflicts], "; ".join(w for _, w in conflicts))
        if self["physics.list_skin"] > 0:
            for key, value, why in (("physics.pressure_solver", "dfsph", "its solves walk lists built every step"),
                                    ("physics.neighbour_search", "all_pairs", "the lists are built from the grid")):
                if self[key] == value:
                    self._refuse("physics.list_skin", [key], why, "set physics.list_skin = 0")
            if self["domain.obstacles"]:
                raise SceneError(f'physics.list_skin = {self["physics.list_skin"]:g} does not go with domain.obstacles '
                                 "(an obstacle's images are chosen at every step); set physics.list_skin = 0")
        if self["physics.shifting"] != "none" and self.dfsph:
            self._refuse("physics.shifting", ["physics.pressure_solver"], "the shift's buffer holds DFSPH's predicted "
                         'velocity in its constant-density solve; use physics.pressure_solver = "state_equation"')
        if self["physics.density_diffusion"] != "none" and self["physics.density"] != "continuity":
            self._refuse("physics.density_diffusion", ["physics.density"], 'it needs physics.density = "continuity": a '
                         "summation density is recomputed from the positions every step, there is nothing to diffuse")

    def _named(self, keys):
        """'key = value and ...' for a message, followed by the model that set them where the scene did not."""
        def shown(group):
            return " and ".join(f"{k} = {json.dumps(self[k]) if isinstance(self[k], str) else f'{self[k]:g}'}"
                                for k in group)
        given, preset = [k for k in keys if k not in self.from_model], [k for k in keys if k in self.from_model]
        by = f"{shown(preset)} (set by {self.from_model[preset[0]]})" if preset else ""
        return " and ".join(part for part in (by, shown(given)) if part)

    def _refuse(self, key, others, why, fix=""):
        """SceneError: `key` does not go with the keys `others` (why), and how to mend it: `fix`, else, where a
        model set some of them, the one model that sets `key` so (where `key` was given), or give the keys the
        model set as well, or drop those given."""
        preset = [k for k in (key, *others) if k in self.from_model]
        given = [k for k in (key, *others) if k not in self.from_model]
        if not fix and preset:
            models = [m for m, keys in PRESETS.items() if keys.get(key) == self[key]]
            fix = f"drop {' and '.join(given)} or give {' and '.join(preset)} as well"
            if given == [key] and len(models) == 1:
                fix = f'set physics.model = "{models[0]}" (it sets {key} so), or give {" and ".join(preset)} as well'
        raise SceneError(f"{self._named([key])} does not go with {self._named(others)} ({why})"
                         + (f"; {fix}" if fix else ""))

    def _check_geometry(self):
        dim = self.dim
        vectors = {"domain.box_min": self["domain.box_min"], "domain.box_max": self["domain.box_max"],
                   "forces.gravity": self["forces.gravity"]}
        for i, block in enumerate(self["fluid.blocks"]):
            vectors[f"fluid.blocks[{i}].min"] = block["min"]
        for i, box in enumerate(self["domain.obstacles"]):
            vectors[f"domain.obstacles[{i}].min"] = box["min"]
        for where, v in vectors.items():
            if len(v) != dim:
                raise SceneError(f"{where} = {v} has {len(v)} components but physics.dimension = {dim}")
        lo, hi = self["domain.box_min"], self["domain.box_max"]
        for axis in range(dim):
            if hi[axis] - lo[axis] <= 2 * self.h:
                raise SceneError(f"domain.box_max - domain.box_min = {hi[axis] - lo[axis]:g} m on axis {axis} must exceed "
                                 f"2 h = {2 * self.h:g} m (h = fluid.spacing * fluid.smoothing_ratio)")
            skin = self.skin_thousandths / 1000
            if skin > 0 and self["domain.boundary"] == "walls" and hi[axis] - lo[axis] <= (2 + 1.5 * skin) * self.h:
                raise SceneError(f"domain.box_max - domain.box_min = {hi[axis] - lo[axis]:g} m on axis {axis} must exceed "
                                 f"(2 + 1.5 physics.list_skin) h = {(2 + 1.5 * skin) * self.h:g} m with reused lists (a "
                                 "particle's wall on each axis is the one it was near at the lists' build)")
        for i, block in enumerate(self["fluid.blocks"]):
            if any(block["min"][a] < lo[a] or block["max"][a] > hi[a] for a in range(dim)):
                raise SceneError(f"fluid.blocks[{i}]: {block} is not inside the box domain.box_min .. domain.box_max = "
                                 f"{lo} .. {hi}")
        self._check_obstacles()
        self._check_overlaps()
        count = sum(np.prod(self._lattice_shape(b)) for b in self["fluid.blocks"])
        if count == 0:
            raise SceneError(f"fluid.blocks: no particle fits at fluid.spacing = {self['fluid.spacing']:g} m")
        most = MAX_PARTICLES * launched_ranks()
        if count > most:
            raise SceneError(f"fluid.blocks: {count} particles at fluid.spacing = {self['fluid.spacing']:g} m "
                             f"exceeds {most}{f' ({MAX_PARTICLES} a rank)' if most > MAX_PARTICLES else ''}; raise the spacing")
        if self["bodies"]:
            self._check_bodies()
            count = self.particle_count()
            if count > most:
                raise SceneError(f"fluid.blocks and bodies: {count} particles (fluid and wall) at fluid.spacing = "
                                 f"{self['fluid.spacing']:g} m exceeds {most}; raise the spacing")
        cells = int(np.prod(self.grid_dim))
        if cells > MAX_CELLS:
            raise SceneError(f"domain: the neighbour grid would need {cells} cells of size {self.cell_size:g} m "
                             f"(at most {MAX_CELLS}); shrink the box (domain.box_min, domain.box_max) or raise "
                             "fluid.spacing")
        self._check_numbers(int(count))
        # (bodies: the names of the scene's [[bodies]], where the scene has that key)
        check_gauge_places(self.config.get("gauges", []), dim, lo, hi,
                           [b.get("name") for b in self.config.get("bodies", []) if isinstance(b, dict)])

    def _check_bodies(self):
        """Bodies: their keys against the scene's dimension and model, then the geometry (_geometry: the meshes
        loaded, each body in the box and thick enough), and no fluid block emptied by the clipping."""
        for i, body in enumerate(self["bodies"]):
            at = geometry.where(i, body)
            if self.dim == 2 and "mesh" in body or self.dim == 3 and "polygon" in body:
                raise SceneError(f"{at}: a {'mesh' if 'mesh' in body else 'polygon'} in a {self.dim}D scene; give "
                                 f"{'polygon' if self.dim == 2 else 'mesh'} (physics.dimension = {self.dim})")
            if (self.dim == 2) != isinstance(body["rotate"], float) or self.dim == 3 and len(body["rotate"]) != 3:
                raise SceneError(f"{at}.rotate = {body['rotate']}: give {'one angle' if self.dim == 2 else '[x, y, z]'} "
                                 f"in degrees (physics.dimension = {self.dim})")
            if len(body["translate"]) != self.dim:
                raise SceneError(f"{at}.translate = {body['translate']} has {len(body['translate'])} components but "
                                 f"physics.dimension = {self.dim}")
            if self.dfsph:
                raise SceneError(f'{at}: bodies need physics.pressure_solver = "state_equation" (the wall particles\' '
                                 f"pressure is extrapolated from the fluid's), not {self._named(['physics.pressure_solver'])}")
            if self["domain.boundary"] == "open":
                raise SceneError(f'{at}: bodies need domain.boundary = "walls" (the wall lattice starts at '
                                 'domain.box_min), not "open"')
        made = self._geometry()
        for i, keep in enumerate(made["keep"]):
            if not keep.any():
                raise SceneError(f"fluid.blocks[{i}] = {self['fluid.blocks'][i]}: no particle left after clipping to the "
                                 "fluid side of the bodies; move the block or the bodies")

    def _geometry(self):
        """The bodies (sphcore.geometry), their wall particles and each fluid block's mask of kept lattice points,
        made once for the keys they come from (read from the geometry cache where it has them). SceneError names
        a body that cannot be read or is not closed, an obstacle outside the box or a container reaching out of
        it, and an obstacle thinner than the wall layer: its deepest point on the wall lattice (the lattice's
        half diagonal added, dx sqrt(dim) / 2, for the deepest point between lattice points) is less than h / 2
        from its surface."""
        dx, h, lo, hi = self["fluid.spacing"], self.h, self["domain.box_min"], self["domain.box_max"]
        key = json.dumps([self["bodies"], self["fluid.blocks"], dx, h, lo, hi])
        if self._made.get("key") == key:
            return self._made
        bodies = [geometry.load_body(i, e) for i, e in enumerate(self["bodies"])]
        for i, body in enumerate(bodies):
            at = geometry.where(i, self["bodies"][i])
            b_lo, b_hi = body.bounds
            if body.fluid == "outside" and any(b_hi[a] <= lo[a] or b_lo[a] >= hi[a] for a in range(self.dim)):
                raise SceneError(f"{at}: outside the box domain.box_min .. domain.box_max = {lo} .. {hi} (its bounds "
                                 f"{b_lo.round(6).tolist()} .. {b_hi.round(6).tolist()})")
            slack = 1e-9 * max(map(abs, lo + hi))
            if body.fluid == "inside" and any(b_lo[a] < lo[a] - slack or b_hi[a] > hi[a] + slack
                                              for a in range(self.dim)):
                raise SceneError(f"{at}: a container whose inside (its bounds {b_lo.round(6).tolist()} .. "
                                 f"{b_hi.round(6).tolist()}) reaches out of the box domain.box_min .. domain.box_max = "
                                 f"{lo} .. {hi}; the fluid side must lie in the box")
            deepest = geometry.body_walls(body, lo, hi, dx, h)[1]
            if body.fluid == "outside" and deepest + dx * math.sqrt(self.dim) / 2 < h / 2:
                raise SceneError(f"{at}: thinner than the wall layer: its deepest point is about "
                                 f"{deepest + dx * math.sqrt(self.dim) / 2:.3g} m from its surface, less than h / 2 = "
                                 f"{h / 2:g} m (h = fluid.spacing * fluid.smoothing_ratio); make it at least h thick")
        walls = geometry.wall_particles(bodies, lo, hi, dx, h)
        keep = [geometry.fluid_mask(bodies, origin - 0.5 * dx, counts, dx)
                for origin, counts in map(self._block_lattice, self["fluid.blocks"])]
        self._made = {"key": key, "bodies": bodies, "walls": walls, "keep": keep}
        return self._made

    @property
    def bodies(self):
        """The loaded bodies (sphcore.geometry.Body: name, fluid side, centroid, shape), in scene order."""
        return self._geometry()["bodies"] if self["bodies"] else []

    def _check_obstacles(self):
        """Obstacles: at most MAX_OBSTACLES, inside the box, and no particle of a block starting
        inside one (strictly: on a face is allowed)."""
        lo, hi, obstacles = self["domain.box_min"], self["domain.box_max"], self["domain.obstacles"]
        if len(obstacles) > MAX_OBSTACLES:
            raise SceneError(f"domain.obstacles: {len(obstacles)} boxes, at most {MAX_OBSTACLES}")
        if obstacles and self["domain.boundary"] != "walls":
            raise SceneError('domain.obstacles need domain.boundary = "walls" (the box is their frame)')
        dx = self["fluid.spacing"]
        for k, box in enumerate(obstacles):
            if any(box["min"][a] < lo[a] or box["max"][a] > hi[a] for a in range(self.dim)):
                raise SceneError(f"domain.obstacles[{k}]: {box} is not inside the box domain.box_min .. "
                                 f"domain.box_max = {lo} .. {hi}")
            for i, block in enumerate(self["fluid.blocks"]):
                origin, counts = self._block_lattice(block)
                axes = [origin[a] + dx * np.arange(n) for a, n in enumerate(counts)]
                if all(((x > box["min"][a]) & (x < box["max"][a])).any() for a, x in enumerate(axes)):
                    raise SceneError(f"fluid.blocks[{i}] = {block}: particles would start inside domain.obstacles[{k}] = "
                                     f"{box}; shrink the block or move the obstacle")

    def _check_overlaps(self):
        """Two fluid blocks that overlap would put two particles where one belongs (identical blocks:
        every particle doubled, at the same place; they fly apart at the sound speed)."""
        blocks = self["fluid.blocks"]
        for i in range(len(blocks)):
            for j in range(i):
                a, b = blocks[j], blocks[i]
                if all(max(a["min"][k], b["min"][k]) < min(a["max"][k], b["max"][k]) for k in range(self.dim)):
                    raise SceneError(f"fluid.blocks[{j}] = {a} and fluid.blocks[{i}] = {b} overlap: their particles "
                                     "would be doubled where they meet; make the blocks touch at most")

    def _check_numbers(self, count):
        """Reject what float32 cannot hold: a folded parameter beyond its range (cohesion at a tiny
        h), or positions so far from the origin that float32 resolves them to more than h / 256
        (the lattice would collapse onto itself)."""
        with np.errstate(over="ignore"):
            params = self.params(count)
        for field in params.dtype.names:
            if not np.isfinite(params[0][field]).all():
                keys = _FOLDED_FROM.get(field, ("fluid.spacing", "fluid.smoothing_ratio"))
                given = ", ".join(f"{k} = {self[k]:g}" for k in keys)
                raise SceneError(f"{given}: the parameter {field} folded from them (h = {self.h:g} m) is beyond "
                                 f"float32; lower {keys[0]} or raise fluid.spacing")
        if self["physics.precision"] != "float32":
            return
        reach = max(abs(c) for c in self["domain.box_min"] + self["domain.box_max"])
        resolution = float(np.spacing(np.float32(reach)))
        if resolution > self.h / 256:
            raise SceneError(f"fluid.spacing = {self['fluid.spacing']:g} m: float32 positions {reach:g} m from the "
                             f"origin are {resolution:.2g} m apart, more than h / 256 (h = {self.h:g} m); move "
                             "domain.box_min and domain.box_max nearer the origin, raise fluid.spacing, or set "
                             'physics.precision = "float64"')

    @property
    def skin_thousandths(self):
        """physics.list_skin in thousandths of h (the shaders' LIST_SKIN)."""
        return round(1000 * self["physics.list_skin"])

    @property
    def reach(self):
        """How far the neighbour search reaches: h, or with reused lists a build's, (1 + list_skin) h."""
        k = self.skin_thousandths
        return self.h * (1000 + k) / 1000 if k else self.h

    @property
    def cell_split(self):
        """Cells to the search's reach (the shaders' CELL_SPLIT): 2 where the reach spans 2.5 fluid.spacing or more
        and the grid of half-width cells fits MAX_CELLS, else 1. A scan tests the particles of the (2 split + 1)^dim
        cells around its own: of half-width cells (2.5 reach)^dim of space instead of (3 reach)^dim, 0.58 of the
        candidates in 3D, 0.69 in 2D, at the cost of 2^dim times the cells and shorter runs of particles. Measured
        (docs/models/neighbours.md): slower at 2 dx, whose half-width cells hold one particle each in 3D; faster at
        2.857 dx and at the engineering model's 4 dx."""
        if self["physics.neighbour_search"] == "all_pairs" or self.reach < 2.5 * self["fluid.spacing"]:
            return 1
        return 2 if int(np.prod(self._grid_dim(2))) <= MAX_CELLS else 1

    @property
    def cell_size(self):
        """The neighbour grid's cells: the search's reach, padded (cells.glsl), over cell_split."""
        return self._cell_size(self.cell_split)

    def _cell_size(self, split):
        return self.reach * CELL_PADDING / split

    @property
    def grid_dim(self):
        """Cells per axis (x, y, z) of the neighbour grid: the box in cells of cell_size;
        an open domain's hash period is at least 2 cell_split + 1 cells, so the cells searched around
        a particle are distinct. (1, 1, 1) for all-pairs neighbours."""
        if self["physics.neighbour_search"] == "all_pairs":
            return (1, 1, 1)
        return self._grid_dim(self.cell_split)

    def _grid_dim(self, split):
        size = self._cell_size(split)
        lo, hi = self["domain.box_min"], self["domain.box_max"]
        dims = [max(1, math.ceil((hi[a] - lo[a]) / size)) for a in range(self.dim)] + [1] * (3 - self.dim)
        if self["domain.boundary"] == "open":
            dims = [max(2 * split + 1, d) for d in dims[:self.dim]] + [1] * (3 - self.dim)
        return tuple(dims)

    def particle_count(self):
        """The particles the scene starts with, fluid and wall (fluid_count() + len(wall_positions()[0]))."""
        return self.fluid_count() + (len(self._geometry()["walls"][1]) if self["bodies"] else 0)

    def fluid_count(self):
        """The fluid particles the scene starts with: counted without making them where it has no bodies, else
        the lattice points the clipping keeps (made once)."""
        if self["bodies"]:
            return int(sum(keep.sum() for keep in self._geometry()["keep"]))
        return int(sum(np.prod(self._lattice_shape(b)) for b in self["fluid.blocks"]))

    def _lattice_shape(self, block):
        dx = self["fluid.spacing"]
        return [int(math.floor((block["max"][a] - block["min"][a]) / dx + 1e-6)) for a in range(len(block["min"]))]

    def _block_lattice(self, block):
        """A fluid block's lattice: (its first point, its points per axis). The cell centres block.min + (i + 0.5) dx;
        where the scene has bodies, the wall lattice's points in the block (domain.box_min + (i + 0.5) dx, strictly
        inside it: fluid and walls on one lattice, as DualSPHysics' GenCase makes them; a fluid particle would
        otherwise start a fraction of dx from a wall particle)."""
        dx = self["fluid.spacing"]
        if not self["bodies"]:
            return np.asarray(block["min"], np.float64) + 0.5 * dx, self._lattice_shape(block)
        origin = geometry.box_lattice(self["domain.box_min"], self["domain.box_max"], dx)[0]
        first = np.ceil((np.asarray(block["min"]) - origin) / dx - 1e-6)
        last = np.floor((np.asarray(block["max"]) - origin) / dx + 1e-6)
        return origin + dx * first, np.maximum(last - first + 1, 0).astype(int).tolist()

    def initial_positions(self):
        """Fluid particles at cell centres of a square (cubic) lattice filling each block, where the scene has
        bodies on the wall lattice (_block_lattice) and only those at least dx / 2 off every body on its fluid side
        (sphcore.geometry), (N, dim), in the scene's precision."""
        dx = self["fluid.spacing"]
        parts = []
        for i, block in enumerate(self["fluid.blocks"]):
            origin, counts = self._block_lattice(block)
            part = np.empty((*counts, self.dim), self._real)  # (each axis' coordinates written across the others)
            for a, k in enumerate(counts):
                part[..., a] = (origin[a] + dx * np.arange(k)).astype(self._real).reshape(
                    [k if b == a else 1 for b in range(self.dim)])
            parts.append(part.reshape(-1, self.dim))
            if self["bodies"]:
                parts[-1] = parts[-1][self._geometry()["keep"][i]]
        return np.concatenate(parts) if len(parts) > 1 else parts[0]

    def wall_positions(self):
        """The bodies' wall particles (Adami et al. 2012's dummy particles): positions (N_w, dim) in the scene's
        precision on the wall lattice domain.box_min + (i + 0.5) dx inside the box, from depth h on each body's
        solid side to the fluid, whose particles start dx / 2 off the surface (the lattice points between are
        walls: sphcore.geometry), body by body in lattice order; and each one's body index (N_w,) int32."""
        if not self["bodies"]:
            return np.zeros((0, self.dim), self._real), np.zeros(0, np.int32)
        x, owner = self._geometry()["walls"]
        return x.astype(self._real), owner.copy()

    @property
    def _real(self):
        return np.float64 if self["physics.precision"] == "float64" else np.float32

    @property
    def mass(self):
        """Each particle's mass [kg; 2D: kg/m]: the mass with which a full lattice's kernel sum is rest_density."""
        return lattice_mass(self["fluid.spacing"], self.h, self["fluid.rest_density"], self.dim, self["physics.kernel"])

    def initial_density(self, positions):
        """Each particle's density at the start (N,), float64. With physics.density = "continuity" the
        density is state: it starts hydrostatic, so that a tank starts at rest, rho = EOS^-1(p) with p the
        hydrostatic_pressure (linear: rho_0 + p / k; Tait: rho_0 (1 + p / B)^(1/7)). Summation
        recomputes it every step: rho_0 here."""
        rho0 = self["fluid.rest_density"]
        if self["physics.density"] != "continuity":
            return np.full(len(positions), rho0)
        p = self.hydrostatic_pressure(positions)
        k = self["fluid.stiffness"]
        if self["physics.equation_of_state"] == "tait":
            return rho0 * (1.0 + p / (rho0 * k / 7.0)) ** (1.0 / 7.0)
        return rho0 + p / k

    def hydrostatic_pressure(self, positions):
        """rho_0 |g_a| depth at each of `positions` (N,), float64: along the axis a that gravity mostly
        points along, depth below the top of the highest block whose column holds the particle (0
        without gravity). Continuity density starts from it (initial_density), and so does DFSPH's
        stiffness sum (the first step's warm start, as every later step's, holds part of it)."""
        x = np.asarray(positions, np.float64)
        rho0 = self["fluid.rest_density"]
        g = np.asarray(self["forces.gravity"], np.float64) if self["physics.gravity"] else np.zeros(self.dim)
        if not g.any():
            return np.zeros(len(x))
        axis = int(np.argmax(np.abs(g)))
        up = -np.sign(g[axis])
        depth = np.zeros(len(x))
        for block in self["fluid.blocks"]:
            others = [a for a in range(self.dim) if a != axis]
            column = np.all([(x[:, a] >= block["min"][a]) & (x[:, a] <= block["max"][a]) for a in others], axis=0)
            top = block["max"][axis] if up > 0 else block["min"][axis]
            depth = np.where(column, np.maximum(depth, up * (top - x[:, axis])), depth)
        return rho0 * abs(g[axis]) * np.maximum(depth, 0.0)

    @property
    def max_neighbours(self):
        """Slots of a neighbour list (spec_for): fluid.max_neighbours, or (0) twice the lattice particles in a
        ball of radius h (pi r^2, 4/3 pi r^3 with r = fluid.smoothing_ratio): the solver holds the density
        within a fraction of a percent of rest, and the wall images fill a ball cut by the walls."""
        if self["fluid.max_neighbours"] > 0:
            return self["fluid.max_neighbours"]
        r = self["fluid.smoothing_ratio"] * (1000 + self.skin_thousandths) / 1000  # (reused lists reach further)
        return math.ceil(2 * (math.pi * r * r if self.dim == 2 else 4 / 3 * math.pi * r ** 3))

    @property
    def spec(self):
        """The scene's compile-time choices (specialization constants of every shader)."""
        physics = self.config["physics"]
        return Spec(DIM=self.dim, GRID=physics["neighbour_search"] == "grid",
                    WALLS=self["domain.boundary"] == "walls", TAIT=physics["equation_of_state"] == "tait",
                    VISCOSITY=physics["viscosity"], SURFACE_TENSION=physics["surface_tension"],
                    GRAVITY=physics["gravity"], NEIGHBOUR_STATS=False, OBSTACLES=len(self["domain.obstacles"]),
                    KERNEL=KERNELS.index(physics["kernel"]), CONTINUITY=physics["density"] == "continuity",
                    DENSITY_DIFFUSION=DENSITY_DIFFUSIONS.index(physics["density_diffusion"]),
                    VISCOSITY_MODEL=("laminar", "artificial").index(physics["viscosity_model"]),
                    NO_SLIP=self["domain.wall_model"] == "no_slip", VERLET=self["time.integrator"] == "verlet",
                    ADAPTIVE_DT=self.adaptive_dt, DFSPH=self.dfsph,
                    MAX_NEIGHBOURS=self.max_neighbours if self.dfsph else 0, LIST_SKIN=self.skin_thousandths,
                    CELL_SPLIT=self.cell_split, SHIFTING=int(physics["shifting"] == "lind"),
                    BODIES=bool(self.config.get("bodies")))

    def spec_for(self, backend):
        """The spec a run on `backend` compiles: the scene's, and with the state equation also neighbour
        lists (MAX_NEIGHBOURS, as DFSPH always has them), which compute_density's scan writes and
        compute_forces walks instead of scanning the cells a second time: the same pairs in the same
        order, so the same bits (a particle with more neighbours than the list's slots is scanned as
        before). Measured, 3D, h = 2 dx: numba 1.67x faster at 64,000 particles, the H200 1.13x at 1 M
        and 1.12x at 8 M. Lists of more than LIST_WORDS[backend] words in all (a large scene, or a large
        fluid.smoothing_ratio) are left out: the scan needs no memory. Under DFSPH on numba, where they fit
        (GRADIENT_SLOTS), dfsph_factor also stores each list entry's gradient for the sweeps (GRADIENTS). numba's
        lists are particle-major, Vulkan's slot-major (LIST_BY_PARTICLE), under the state equation in chunks of 4
        slots (LIST_CHUNKS: dfsph.glsl; sphcore.backends.list_entries reads each in particle order)."""
        from sphcore.sph.dfsph import list_width  # (numba: loaded where a run starts, not to read a scene)

        spec = self.spec
        if not spec.DFSPH and self.particle_count() * list_width(self.max_neighbours) <= LIST_WORDS.get(backend, 0):
            spec = spec._replace(MAX_NEIGHBOURS=self.max_neighbours)
        if spec.DFSPH and self.particle_count() * list_width(spec.MAX_NEIGHBOURS) <= GRADIENT_SLOTS.get(backend, 0):
            spec = spec._replace(GRADIENTS=True)  # (dfsph_factor stores what the sweeps would compute)
        listed = spec.MAX_NEIGHBOURS > 0
        if spec.LIST_SKIN and not listed:
            raise SceneError(f"physics.list_skin = {self['physics.list_skin']:g}: the {backend} backend holds at most "
                             f"{LIST_WORDS.get(backend, 0)} list words, and {self.particle_count()} particles with "
                             f"{list_width(self.max_neighbours)} slots each need more; set physics.list_skin = 0")
        return spec._replace(LIST_BY_PARTICLE=backend == "numba" and listed,
                             LIST_CHUNKS=backend == "vulkan" and listed and not spec.DFSPH)

    def params(self, n, fluid_count=None):
        """The folded parameter block for n particles, the first `fluid_count` (default all) the fluid's
        (sphcore.params.PARAMS_DTYPE)."""
        return fold_parameters(
            n=n, dim=self.dim, h=self.h, mass=self.mass, rest_density=self["fluid.rest_density"],
            stiffness=self["fluid.stiffness"], tait=self["physics.equation_of_state"] == "tait",
            viscosity=self["fluid.viscosity"], cohesion=self["fluid.cohesion"], dt=self._folded_dt(),
            restitution=self["walls.restitution"], gravity=self["forces.gravity"],
            box_min=self["domain.box_min"], box_max=self["domain.box_max"], grid_dim=self.grid_dim,
            kernel=self["physics.kernel"], density_diffusion=self["physics.density_diffusion"],
            diffusion_delta=self["fluid.density_diffusion"], gravity_on=self["physics.gravity"],
            viscosity_model=self["physics.viscosity_model"], alpha=self["fluid.alpha"],
            cfl_number=(self["time.cfl_number"] / self["fluid.smoothing_ratio"] if self.dfsph
                        else 0.25 * self["time.dt_fraction"] if self.adaptive_dt else 0.0),
            reach=self.reach, cell_split=self.cell_split, spacing=self["fluid.spacing"],
            shifting=self["fluid.shifting"] if self["physics.shifting"] != "none" else 0.0, fluid_count=fluid_count)

    def to_json(self):
        """Every key as JSON (what scene.json and final.npz keep; Scene.from_dict(json.loads(...)) reads it)."""
        return json.dumps(self.config, sort_keys=True)


def preset_note(dotted):
    """What each physics.model sets `dotted` to, for the meaning of a key a model sets ("" for the others)."""
    if dotted not in PRESETS[DEFAULT_MODEL]:
        return ""
    return " (physics.model: " + ", ".join(f"{m} {json.dumps(keys[dotted])}" for m, keys in PRESETS.items()) + ")"


def describe_schema(schema=SCHEMA, prefix=""):
    """Lines of `key  default  unit  range  doc` for every key (for `sphcore keys` and docs/scenes.md); the
    default of a key that physics.model sets is DEFAULT_MODEL's, and its meaning ends with every model's value."""
    lines = []
    for name, key in schema.items():
        path = f"{prefix}{name}"
        if isinstance(key, dict):
            lines += describe_schema(key, f"{path}.")
        else:
            span = (key.kind if "|" in key.kind else "" if key.kind in ("str", "bool", "gauges")
                    else f"[{key.low:g}, {key.high:g}]")
            lines.append(f"{path:24} {json.dumps(key.default):>12}  {key.unit:8} {span:18} {key.doc}{preset_note(path)}")
    return lines
