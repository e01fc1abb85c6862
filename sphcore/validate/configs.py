"""Named model configurations of the validation cases (issue 12), and the physics switches a case
takes one by one.

A configuration is a set of scene keys (dotted names) laid over the scene a validation case
builds over the graphics model (`physics.model = "graphics"`, which each case names); "graphics" adds
none (Mueller's kernels, summation density, Mueller's laminar viscosity, free-slip mirror walls,
symplectic Euler),
"engineering" is the recommended model for measured figures (Wendland C2, continuity density
with density diffusion, Monaghan's artificial viscosity, velocity Verlet), the configuration of
TrixiParticles' 2D dam break (examples/fluid/dam_break_2d.jl: Wendland C2 with smoothing length
2 dx, so support radius 4 dx, continuity density, Molteni-Colagrossi diffusion with delta = 0.1,
artificial viscosity alpha = 0.02 on the smoothing length, linear equation of state at
c = 20 sqrt(g H)). Our h is the support radius: fluid.smoothing_ratio = 4 and alpha = 0.01 are the
same model. Measured on the hydrostatic tank (continuity, Wendland C2, 20 particles per depth):
at a support radius of 2 dx the settled pressure's slope is 6.7 % steep (the kernel gradient's
lattice sum is that far from exact with about 12 neighbours), at 3 dx 1.1 % shallow, at 4 dx
within 0.3 %. The other names switch one model at a time from
"graphics", so the sweep can say which switch buys what.

A configuration whose keys this build's scene schema does not have is refused in one line naming
them (`require`), so a validation run never silently measures another model than it names.
"""
from sphcore.scene import SCHEMA, Key, SceneError

# option name -> (scene key, values allowed where the schema does not say): the switches a
# validation case takes one by one (`--kernel`, `--density`, ...)
SWITCHES = {
    "kernel": ("physics.kernel", ("mueller", "wendland_c2")),
    "density": ("physics.density", ("summation", "continuity")),
    "density_diffusion": ("physics.density_diffusion", ("none", "molteni", "fourtakas")),
    "delta": ("fluid.density_diffusion", None),
    "viscosity_model": ("physics.viscosity_model", ("laminar", "artificial")),
    "wall_model": ("domain.wall_model", ("free_slip", "no_slip")),
    "integrator": ("time.integrator", ("symplectic_euler", "verlet")),
    "pressure_solver": ("physics.pressure_solver", ("state_equation", "dfsph")),  # issue 14
    "relaxation": ("fluid.relaxation", None),  # DFSPH's omega
    "cfl_number": ("time.cfl_number", None),  # DFSPH's step: the CFL number on the particle speed
    "shifting": ("physics.shifting", ("none", "lind")),  # issue 31: Lind et al. 2012's particle shifting
}
OPTIONS = (*SWITCHES, "adaptive_dt")  # the settings a case takes beside "config"
ALPHA_KEY = "fluid.alpha"  # Monaghan's alpha of the artificial viscosity model

ENGINEERING = {"physics.kernel": "wendland_c2", "physics.density": "continuity",
               "physics.density_diffusion": "molteni", "fluid.density_diffusion": 0.1,
               "physics.viscosity_model": "artificial", "fluid.alpha": 0.01, "time.integrator": "verlet",
               "fluid.smoothing_ratio": 4.0}
CONFIGS = {
    "graphics": {},
    "engineering": ENGINEERING,
    # one switch at a time from "graphics"
    "wendland": {"physics.kernel": "wendland_c2"},
    "continuity": {"physics.density": "continuity", "physics.density_diffusion": "molteni",
                   "fluid.density_diffusion": 0.1},
    "artificial": {"physics.viscosity_model": "artificial"},
    "no_slip": {"domain.wall_model": "no_slip"},
    "verlet": {"time.integrator": "verlet"},
    # the recommended model with no-slip walls
    "engineering_no_slip": {**ENGINEERING, "domain.wall_model": "no_slip"},
    # the recommended model on the scenes' support radius h = 2 dx (alpha as on h = 4 dx)
    "engineering_h2": {**ENGINEERING, "fluid.smoothing_ratio": 2.0, "fluid.alpha": 0.02},
    # the recommended model with Fourtakas et al.'s diffusion (its hydrostatic part removed)
    "engineering_fourtakas": {**ENGINEERING, "physics.density_diffusion": "fourtakas"},
    # issue 14: the incompressible pressure solver (DFSPH) in place of the state equation
    "dfsph": {"physics.pressure_solver": "dfsph"},
    # DFSPH for water that must come to rest: Wendland C2 on 2 dx, 0.8 of each Jacobi update (a tank at rest:
    # 0.0007 against 0.062 m/s median speed with "dfsph"; the same Martin & Moyce front as omega = 1)
    "dfsph_wendland": {"physics.pressure_solver": "dfsph", "physics.kernel": "wendland_c2", "fluid.relaxation": 0.8},
    # issue 15: "graphics" with its neighbour lists reused between builds (the same pairs: a speed switch only)
    "list_skin": {"physics.list_skin": 0.1},
    # issue 15: the recommended model with its neighbour lists reused between builds (continuity density: the walks
    # add each pair's rate)
    "engineering_list_skin": {**ENGINEERING, "physics.list_skin": 0.1},
    # the recommended model with summation density (no continuity, no diffusion)
    "engineering_summation": {k: v for k, v in ENGINEERING.items() if k not in (
        "physics.density", "physics.density_diffusion", "fluid.density_diffusion")},
    # issue 31: the recommended model with Lind et al. 2012's particle shifting (A = 2, DualSPHysics' ShiftCoef;
    # docs/models/shifting.md)
    "engineering_shifting": {**ENGINEERING, "physics.shifting": "lind", "fluid.shifting": 2.0},
}
DEFAULT_CONFIG = "graphics"
RECOMMENDED_CONFIG = "engineering"


def schema_key(dotted):
    """The schema's Key of `dotted`, or None where this build has no such key."""
    node = SCHEMA
    for part in dotted.split("."):
        if not isinstance(node, dict) or part not in node:
            return None
        node = node[part]
    return node if isinstance(node, Key) else None


def choices(option):
    """The values `--<option>` takes: the schema's where it has the key, else the planned ones."""
    key, planned = SWITCHES[option]
    found = schema_key(key)
    if found is not None and "|" in found.kind:
        return tuple(found.kind.split("|"))
    return planned


def overrides(settings):
    """The scene keys of settings["config"] with the switches given in `settings` laid over them;
    {"physics.viscosity_model": "artificial"} brings fluid.alpha = settings["alpha"] with it."""
    name = settings.get("config") or DEFAULT_CONFIG
    if name not in CONFIGS:
        raise SceneError(f"--config {name}: no such configuration (known: {', '.join(CONFIGS)})")
    out = dict(CONFIGS[name])
    for option, (key, _) in SWITCHES.items():
        if settings.get(option) is not None:
            out[key] = settings[option]
    if (out.get("physics.viscosity_model") == "artificial" and settings.get("alpha") is not None
            and ALPHA_KEY not in CONFIGS[name]):  # a configuration's own alpha goes with its smoothing ratio
        out[ALPHA_KEY] = settings["alpha"]
    if settings.get("adaptive_dt"):
        out["time.dt"] = "adaptive"
    return out


def require(keys, what="the configuration"):
    """SceneError naming the keys of `keys` this build's scene schema does not have."""
    missing = sorted(k for k in keys if schema_key(k) is None)
    if missing:
        raise SceneError(f"{what} needs scene keys this build does not have: {', '.join(missing)} "
                         "(`sphcore keys` lists those it has)")


def apply(data, keys):
    """The scene dict `data` (nested, as a TOML file parses) with the dotted `keys` set in it."""
    require(keys)
    for dotted, value in keys.items():
        *tables, name = dotted.split(".")
        node = data
        for t in tables:
            node = node.setdefault(t, {})
        node[name] = value
    return data


def describe(name_or_keys):
    """A one-line description of a configuration: its name and keys."""
    keys = CONFIGS[name_or_keys] if isinstance(name_or_keys, str) else name_or_keys
    body = ", ".join(f"{k} = {v}" for k, v in keys.items()) or "the scene defaults"
    return f"{name_or_keys}: {body}" if isinstance(name_or_keys, str) else body
