"""The switch matrix (issue 30): every combination of the scene's switches runs a few steps on numba and on
Vulkan (lavapipe), and the two must agree: integers (the sorted particle ids, the grid's counts, the neighbour
counts, DFSPH's iteration counts, the lists' builds) bit for bit, reals within FLOAT_RTOL.

The whole product (SWITCHES, refused combinations left out) is benchmarks/switch_matrix.py's; CI runs a covering
sample of it (`covering_sample`: every pair of switch values that some accepted combination holds, so every value
of every switch, DFSPH with Wendland C2 among them), drawn in a fixed order (SEED). A combination the scene
validation refuses is checked to be refused with a SceneError. Tiny scenes: a 2D block of 225 particles or a 3D
one of 216, beside an obstacle when domain.obstacles is on, STEPS steps. Each combination compiles its own numba
mirrors: the file takes about 20 s with the numba cache warm, 4 minutes of CPU with it cold.
"""
import functools
import itertools
import math

import numpy as np
import pytest

from conftest import BACKENDS, VALIDATION, scene_changed, schema_keys, vulkan_or_skip
from sphcore.backends import in_particle_order
from sphcore.paths import SCENE_DIR
from sphcore.scene import SceneError
from sphcore.simulation import Simulation
from sphcore.sph.dfsph import (CONTROL_BUILDS, CONTROL_FAILURES, CONTROL_ITERATIONS, CONTROL_OVERFLOW_STEP,
                               CONTROL_STEP, SOLVE_DENSITY, SOLVE_DIVERGENCE)

# scene key -> the values a user can set (`sphcore keys`; sphcore/scene.py SCHEMA). A named choice lists every
# choice the schema offers (test_switches_are_the_schemas_choices); list_skin and the obstacles are on or off
SWITCHES = {
    "physics.dimension": (2, 3),
    "physics.precision": ("float32", "float64"),
    "physics.kernel": ("mueller", "wendland_c2"),
    "physics.density": ("summation", "continuity"),
    "physics.density_diffusion": ("none", "molteni", "fourtakas"),
    "physics.viscosity_model": ("laminar", "artificial"),
    "physics.equation_of_state": ("linear", "tait"),
    "physics.pressure_solver": ("state_equation", "dfsph"),
    "physics.list_skin": (0.0, 0.2),
    "domain.wall_model": ("free_slip", "no_slip"),
    "domain.obstacles": ("none", "box"),
    "time.integrator": ("symplectic_euler", "verlet"),
    "time.dt": ("auto", "adaptive"),
    "physics.shifting": ("none", "lind"),
    "bodies": ("none", "obstacle"),
}
SEED = 30  # the sample's order of candidates (issue 30)
SAMPLE_SIZE = 12  # at most; the sample ends once every pair is covered
# the sample's first combination: issue 30's dam break (DFSPH with Wendland C2 in float32), whose iteration counts
# differed between the backends from the first step until dfsph_residual's compression was made `precise`
ISSUE_30 = {"physics.dimension": 2, "physics.precision": "float32", "physics.kernel": "wendland_c2",
            "physics.density": "summation", "physics.density_diffusion": "none", "physics.viscosity_model": "laminar",
            "physics.equation_of_state": "linear", "physics.pressure_solver": "dfsph", "physics.list_skin": 0.0,
            "domain.wall_model": "free_slip", "domain.obstacles": "none", "time.integrator": "symplectic_euler",
            "time.dt": "auto", "physics.shifting": "none", "bodies": "none"}
STEPS = 6

# a water block at rest in a tank, in the tank's corner; the obstacle a box beside it, within h of its particles
BASE = {
    2: {"name": "matrix", "physics": {"model": "graphics"}, "domain": {"box_min": [0.0, 0.0], "box_max": [0.3, 0.2]},
        "fluid": {"spacing": 0.01, "blocks": [{"min": [0.0, 0.0], "max": [0.15, 0.15]}]},
        "forces": {"gravity": [0.0, -9.81]}},
    3: {"name": "matrix", "physics": {"model": "graphics"}, "domain": {"box_min": [0.0, 0.0, 0.0], "box_max": [0.24, 0.16, 0.12]},
        "fluid": {"spacing": 0.02, "blocks": [{"min": [0.0, 0.0, 0.0], "max": [0.12, 0.12, 0.12]}]},
        "forces": {"gravity": [0.0, -9.81, 0.0]}},
}
OBSTACLE = {2: {"min": [0.16, 0.0], "max": [0.2, 0.04]}, 3: {"min": [0.14, 0.0, 0.02], "max": [0.18, 0.04, 0.1]}}
# the body (bodies = "obstacle"): beyond the box obstacle, within h of the particles that flow there; 2D a triangle,
# 3D SPHERIC test 2's box obstacle (the shipped mesh) scaled to 0.04 x 0.04 x 0.1 m
BODY = {2: {"name": "wedge", "polygon": [[0.21, 0.0], [0.27, 0.0], [0.21, 0.06]]},
        3: {"name": "box", "mesh": str(SCENE_DIR / "meshes" / "spheric_box.stl"), "scale": 0.25,
            "translate": [0.19 - 0.25 * 0.6635, 0.0, 0.01 - 0.25 * 0.2985]}}

# Reals: the mirrors and the shaders sum the same terms in the same order, and on lavapipe every combination
# measured ends bit for bit equal (benchmarks/results/switch_matrix.json). The tolerance is for what a driver
# may still do: SPIR-V arithmetic not marked `precise` may be reassociated or fused by its compiler (issue 30
# was one such rewrite, where the result decided a branch), and its sqrt and division may round otherwise, an
# ulp here and there that a few steps carry on; as in test_backends, that stays below 1e-5 of each buffer's
# largest magnitude (the pressure's scale at least rho_0 c^2: near rest the equation of state cancels). A pair
# missed or a solve stopped an iteration apart moves them by 1e-3 or more (issue 30, before its fix: 0.13 of the
# velocities with Wendland C2; with Mueller's kernel, the same iterations but other particles warm-started, 2.6e-5).
FLOAT_RTOL = 1e-5
FLOATS = ("particle_x", "particle_v", "particle_rho", "particle_p")
# Integers, bit for bit: the sort's permutation, the grid's cells and counts, the lists' lengths
INTEGERS = ("particle_id", "particle_cell", "cell_start", "grid_status", "neighbour_count")
# control's words that both backends keep alike (the Vulkan host also keeps windows of recorded iterations:
# CONTROL_WINDOW, CONTROL_RUNNING; numba records none)
CONTROL_WORDS = {"divergence iterations": CONTROL_ITERATIONS + SOLVE_DIVERGENCE,
                 "density iterations": CONTROL_ITERATIONS + SOLVE_DENSITY, "solver steps": CONTROL_STEP,
                 "unconverged solves": CONTROL_FAILURES, "overflow step": CONTROL_OVERFLOW_STEP,
                 "list builds": CONTROL_BUILDS}


def combinations():
    """Every combination of SWITCHES, as {key: value} dicts, in the product's order."""
    return [dict(zip(SWITCHES, values)) for values in itertools.product(*SWITCHES.values())]


def scene_of(combo):
    """The Scene of one combination (a SceneError where the validation refuses it)."""
    dim = combo["physics.dimension"]
    changes = dict(combo)
    changes["domain.obstacles"] = [OBSTACLE[dim]] if combo["domain.obstacles"] == "box" else []
    base = {**BASE[dim], "bodies": [BODY[dim]] if changes.pop("bodies") == "obstacle" else []}
    return scene_changed(base, **changes)


def accepted(combos):
    """(combinations the scene validation accepts, {index in combos: the SceneError of each refused one})."""
    ok, refused = [], {}
    for k, combo in enumerate(combos):
        try:
            scene_of(combo)
        except SceneError as e:
            refused[k] = e
        else:
            ok.append(combo)
    return ok, refused


def pairs_of(combo):
    """The pairs ((key, value), (key, value)) of switch values that a combination holds."""
    return set(itertools.combinations(combo.items(), 2))


def covering_sample(combos, size=SAMPLE_SIZE, seed=SEED, first=(ISSUE_30,)):
    """At most `size` of `combos`: `first`, then picks chosen greedily to cover every pair of switch values that
    some combination holds (hence every value of every switch): each pick holds the most pairs not yet covered,
    the first in a seeded shuffle among equals. Not random-only: a random draw of this size leaves pairs out."""
    order = [combos[k] for k in np.random.default_rng(seed).permutation(len(combos))]
    uncovered = set().union(*map(pairs_of, order))
    sample = list(first)
    for combo in sample:
        uncovered -= pairs_of(combo)
    while uncovered and len(sample) < size:
        best = max(order, key=lambda combo: len(pairs_of(combo) & uncovered))
        sample.append(best)
        uncovered -= pairs_of(best)
    return sample


def label(combo):
    """A short id of a combination: its values in SWITCHES' order."""
    return "-".join(str(v) for v in combo.values())


def run_both(combo, steps=STEPS, validation=VALIDATION):
    """{backend: (every buffer after `steps` steps, DFSPH's solver log or None, dim)} of one combination."""
    scene = scene_of(combo)
    out = {}
    for backend in BACKENDS:
        options = {"validation": validation} if backend == "vulkan" else {}
        with Simulation(scene, backend, **options) as sim:
            sim.advance(steps)
            raw = sim.backend.read()
            messages = list(sim.backend.ctx.validation_messages) if backend == "vulkan" else []
            assert messages == [], f"Vulkan validation errors: {messages}"
            out[backend] = raw, sim.solver_log.array() if scene.dfsph else None, scene.dim
    return out, scene


def differences(out, scene):
    """{name: (kind, value)} between the backends: ("int", True where equal) for the integers, the control
    words and DFSPH's iteration counts per step; ("float", max |difference| / scale) for the reals in particle
    order."""
    (a, log_a, dim), (b, log_b, _) = out["numba"], out["vulkan"]
    found = {}
    for name in INTEGERS:
        if name in a:
            found[name] = ("int", bool(np.array_equal(a[name], b[name])))
    for name, word in CONTROL_WORDS.items():
        found[name] = ("int", bool(a["control"][word] == b["control"][word]))
    if log_a is not None:  # step, divergence iterations, density iterations, both converged
        found["solver log iterations"] = ("int", bool(np.array_equal(log_a[:, [0, 3, 5, 7]], log_b[:, [0, 3, 5, 7]])))
    pa, pb = in_particle_order(a, dim), in_particle_order(b, dim)
    least = {"particle_p": scene["fluid.rest_density"] * scene["fluid.stiffness"]}
    for name in FLOATS:
        x, y = np.asarray(pa[name], np.float64), np.asarray(pb[name], np.float64)
        scale = max(float(np.abs(x).max(initial=0.0)), least.get(name, 0.0), 1e-300)
        found[name] = ("float", float(np.abs(x - y).max(initial=0.0)) / scale)
    return found


def failures(found, rtol=FLOAT_RTOL):
    """The differences that break the matrix's promise, as lines."""
    return [f"{name}: {'differs' if kind == 'int' else f'{value:.3g} of its scale > {rtol:g}'}"
            for name, (kind, value) in found.items()
            if (kind == "int" and not value) or (kind == "float" and not value <= rtol)]


ALL = combinations()


@functools.lru_cache(maxsize=None)
def matrix():
    """(accepted combinations, refused ones' errors by index into ALL, the CI sample): validated once, when a test
    first needs them (the product's 12,288 scenes take seconds, too long for every collection)."""
    valid, refused = accepted(ALL)
    return valid, refused, covering_sample(valid)


def test_switches_are_the_schemas_choices():
    """A named choice in SWITCHES lists every choice of its key (a new choice must join the matrix), and every
    switch is a scene key."""
    keys = dict(schema_keys())
    for name, values in SWITCHES.items():
        assert name in keys, name
        if "|" in keys[name].kind:
            assert list(values) == keys[name].kind.split("|"), name


def test_every_combination_is_accepted_or_refused_with_a_scene_error():
    """The validation refuses some combinations (REFUSED, each a SceneError naming a switch it sets, with no
    other exception); every value of every switch runs in some accepted one."""
    VALID, REFUSED, _ = matrix()
    assert len(VALID) + len(REFUSED) == len(ALL) == math.prod(len(v) for v in SWITCHES.values())
    assert VALID and REFUSED
    for k, error in REFUSED.items():
        assert isinstance(error, SceneError)
        assert any(name in str(error) for name in ALL[k]), f"{ALL[k]}: {error}"
    for name, values in SWITCHES.items():
        assert {combo[name] for combo in VALID} == set(values), name
    # what the keys' documentation says does not go together
    refused = [ALL[k] for k in REFUSED]
    assert all(any(combo[name] == value for combo in refused) for name, value in (
        ("physics.density", "continuity"), ("time.integrator", "verlet"), ("physics.list_skin", 0.2)))
    assert not any(c["physics.pressure_solver"] == "dfsph" and c["physics.density"] == "continuity" for c in VALID)
    assert not any(c["physics.density"] == "summation" and c["physics.density_diffusion"] != "none" for c in VALID)


def test_the_sample_covers_every_pair_of_values():
    """The CI sample holds every pair of values that some accepted combination holds: every value of every switch,
    and DFSPH with Wendland C2 (issue 30), each accepted by the validation."""
    VALID, _, SAMPLE = matrix()
    assert len(SAMPLE) <= SAMPLE_SIZE
    assert set().union(*map(pairs_of, SAMPLE)) == set().union(*map(pairs_of, VALID))
    assert all(combo in VALID for combo in SAMPLE)
    assert SAMPLE[0] == ISSUE_30 and ISSUE_30["physics.pressure_solver"] == "dfsph"
    assert covering_sample(VALID) == SAMPLE  # (fixed: the same sample on every run)


def test_failures_names_what_differs():
    """The comparison's verdict: an integer that differs, a real beyond the tolerance, a NaN."""
    found = {"particle_id": ("int", True), "density iterations": ("int", False), "particle_x": ("float", 2e-5),
             "particle_v": ("float", 1e-6), "particle_p": ("float", float("nan"))}
    assert failures(found) == ["density iterations: differs", "particle_x: 2e-05 of its scale > 1e-05",
                               "particle_p: nan of its scale > 1e-05"]


@pytest.mark.vulkan
@pytest.mark.parametrize("k", range(SAMPLE_SIZE))
def test_both_backends_agree(k):
    """Combination k of the sample, STEPS steps on numba and lavapipe: integers bit for bit, reals within
    FLOAT_RTOL (see above)."""
    sample = matrix()[2]
    if k >= len(sample):
        pytest.skip(f"the sample covers every pair in {len(sample)} combinations")
    vulkan_or_skip()
    combo = sample[k]
    out, scene = run_both(combo)
    found = differences(out, scene)
    assert not failures(found), f"{label(combo)}: {failures(found)}"
    if scene.dfsph:  # the solves ran: iterations were counted on both
        log = out["numba"][1]
        assert len(log) == STEPS and (log[:, 5] >= 2).all()
