"""Issue 12, items 4-6: the viscosity model (laminar | artificial), the wall model (free_slip |
no_slip), the integrator (symplectic_euler | verlet) and the adaptive time step, on both backends.

Most tests share one scene's switches (MODELS: artificial viscosity, no-slip walls, Verlet, dt
adaptive), so the numba mirrors are compiled once for them (about 20 s on 2 cores per set of
specialization constants).
"""
import math

import numpy as np
import pytest
from conftest import BACKENDS, assert_stage_agrees, particles, scene_state, vulkan_or_skip

from sphcore.backends import empty_state, plan
from sphcore.scene import Scene, SceneError
from sphcore.simulation import CARRIED, CHECKPOINT, Simulation, resume, run

f32 = np.float32
MODELS = {"physics": {"viscosity_model": "artificial"}, "domain": {"wall_model": "no_slip"},
          "time": {"integrator": "verlet", "dt": "adaptive"}}


def scene_of(*tables):
    """A scene of the graphics model from nested dicts merged table by table (later ones win)."""
    data = {"physics": {"model": "graphics"}}
    for t in tables:
        for k, v in t.items():
            data[k] = {**data.get(k, {}), **v} if isinstance(v, dict) else v
    return Scene.from_dict(data)


# A small 2D column in a 1 m box (375 particles), the MODELS switched on.
COLUMN = {"fluid": {"spacing": 0.02, "blocks": [{"min": [0.0, 0.0], "max": [0.3, 0.5]}]}}


def test_keys_defaults_spec_and_plan():
    default = scene_of(COLUMN)  # the graphics model's keys
    assert (default["physics.viscosity_model"], default["domain.wall_model"], default["time.integrator"],
            default["fluid.alpha"]) == ("laminar", "free_slip", "symplectic_euler", 0.02)
    spec = default.spec
    assert (spec.VISCOSITY_MODEL, spec.NO_SLIP, spec.VERLET, spec.ADAPTIVE_DT) == (0, False, False, False)
    names = [s.name for s in plan(default)]
    assert "reduce_dt" not in names and "choose_dt" not in names  # compiled out: not in the plan at all
    models = scene_of(COLUMN, MODELS)
    spec = models.spec
    assert (spec.VISCOSITY_MODEL, spec.NO_SLIP, spec.VERLET, spec.ADAPTIVE_DT) == (1, True, True, True)
    assert [s.name for s in plan(models)][-4:] == ["compute_forces", "reduce_dt", "choose_dt", "integrate"]
    verlet = scene_of(COLUMN, {"time": {"integrator": "verlet"}})
    assert [s.name for s in plan(verlet)][-3:] == ["compute_forces", "choose_dt", "integrate"]  # the last dt
    # folded: artificial viscosity's alpha c h in viscosity_coef; the CFL number; P.dt the viscous cap
    p = models.params(10)[0]
    assert p["viscosity_coef"] == f32(0.02 * 20.0 * models.h)
    assert p["cfl_number"] == f32(0.25) and default.params(10)[0]["cfl_number"] == 0
    mu = 0.02 * 1000.0 * 20.0 * models.h / 8  # its shear viscosity, alpha rho_0 c h / (2 dim + 4)
    assert p["dt"] == f32(0.125 * models.h ** 2 * 1000.0 / mu)


@pytest.mark.parametrize("table, key, value", [
    ("physics", "viscosity_model", "monaghan"), ("physics", "viscosity_model", 1),
    ("domain", "wall_model", "noslip"), ("domain", "wall_model", True),
    ("time", "integrator", "rk4"), ("time", "integrator", "Verlet"),
    ("time", "dt", "adaptve"), ("time", "dt", -1.0),
    ("fluid", "alpha", -0.1), ("fluid", "alpha", 11.0), ("fluid", "alpha", "0.02"),
])
def test_bad_values_are_rejected_naming_the_key(table, key, value):
    with pytest.raises(SceneError, match=rf"{table}\.{key}"):
        scene_of(COLUMN, {table: {key: value}})


@pytest.mark.parametrize("switches", [MODELS, {"time": {"integrator": "verlet"}}], ids=["models", "verlet"])
def test_each_stage_agrees_between_backends(open_backend, switches):
    """Every stage of the plan once, from a jittered state with random velocities: integers and the
    device's dt (time_state, dt_partial) bitwise, reals within 1e-5 of each buffer's scale (the
    tolerance of tests/test_backends.py). Then 20 whole steps: positions within 1e-6 of the spacing."""
    scene = scene_of(COLUMN, switches)
    state, params, stages, spec = scene_state(scene, jitter=0.3, seed=3)
    state["particle_v"][:, :2] = np.random.default_rng(4).normal(0, 1, (len(state["particle_v"]), 2))
    cpu = open_backend("numba", params, state, stages, spec)
    gpu = open_backend("vulkan", params, state, stages, spec)
    for _ in range(2):  # the second time round, Verlet's half-step velocity and the last dt are in use
        for stage in stages:
            cpu.run_stage(stage)
            gpu.run_stage(stage)
            a, b = cpu.read(), gpu.read()
            assert_stage_agrees(a, b, stage, 1e-5)
            assert np.array_equal(a["time_state"], b["time_state"]), f"after {stage}: {a['time_state']} {b['time_state']}"
    assert a["time_state"][0, 0] > 0 and a["time_state"][0, 1] > 0
    cpu.step(20)
    gpu.step(20)
    gap = np.abs(particles(cpu, 2)["particle_x"] - particles(gpu, 2)["particle_x"]).max()
    assert gap <= 1e-6 * scene["fluid.spacing"], gap
    assert np.array_equal(cpu.read()["time_state"], gpu.read()["time_state"])


@pytest.mark.parametrize("local_size", [128, 8])
@pytest.mark.parametrize("backend", BACKENDS)
def test_adaptive_dt_reacts_to_a_fast_particle_within_one_step(open_backend, backend, local_size):
    """A particle launched at 50 m/s (c = 20 m/s): the first step's dt is the CFL bound of that speed,
    cfl_number h / (c + |v|), computed on the host in float32 as the device does, bitwise. (Work
    groups of 8: 47 partials, more than choose_dt's one group of 8 invocations.)"""
    scene = scene_of(COLUMN, MODELS)
    state, params, stages, spec = scene_state(scene)
    top = int(np.argmax(state["particle_x"][:, 0] + state["particle_x"][:, 1]))  # sorted last: the last partial
    state["particle_v"][top, :2] = [0.0, 50.0]  # upwards, away from the fluid: no viscous kick
    backend_ = open_backend(backend, params, state, stages, spec, local_size=local_size)
    backend_.step(1)
    dt = backend_.read()["time_state"][0, 0]
    P = params[0]
    v2 = f32(0.0) * f32(0.0) + f32(50.0) * f32(50.0)
    cfl = P["cfl_number"] * P["h"] / (np.sqrt(P["stiffness"]) + np.sqrt(v2))
    assert dt == cfl, (dt, cfl)
    assert math.isclose(dt, scene["time.dt_fraction"] * 0.25 * scene.h / (20.0 + 50.0), rel_tol=1e-6)
    assert dt < 0.5 * scene.dt  # the estimate before the step (free fall from the top of the column)
    assert backend_.read()["time_state"][0, 2] == dt  # the time: one step of dt


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_ranks_choose_dt_writes_the_largest_partial_first(open_backend, backend):
    """On a rank (sphcore.parallel: Rank.reduce_dt), choose_dt at level 1 writes the largest |v|^2 and |a|^2 of
    reduce_dt's partials as the first partial: numpy's maximum of the partials, bitwise (work groups of 8: 47
    partials, the fast particle's in the last); the other partials and the time stay as they were."""
    from sphcore.stage import Stage
    scene = scene_of(COLUMN, MODELS)
    state, params, stages, spec = scene_state(scene)
    top = int(np.argmax(state["particle_x"][:, 0] + state["particle_x"][:, 1]))  # sorted last: the last partial
    state["particle_v"][top, :2] = [0.0, 50.0]
    sim = open_backend(backend, params, state, stages, spec, local_size=8)
    names = [stage.name for stage in stages]
    for stage in stages[:names.index("reduce_dt") + 1]:
        sim.run_stage(stage)
    before = sim.read()
    sim.run_stage(Stage("choose_dt", 1))
    after = sim.read()
    partials = before["dt_partial"][:-(-len(state["particle_x"]) // 8)]
    assert len(partials) == 47 and partials[-1, 0] == np.float32(2500.0) and partials[0, 0] < 2500.0
    assert np.array_equal(after["dt_partial"][0], partials.max(axis=0))
    assert partials[:, 1].argmax() != 0 and after["dt_partial"][0, 1] > partials[0, 1]  # (|a|^2 too)
    assert np.array_equal(after["dt_partial"][1:], before["dt_partial"][1:])
    assert np.array_equal(after["time_state"], before["time_state"])


@pytest.mark.parametrize("backend", BACKENDS)
def test_momentum_is_conserved_with_the_models(open_backend, backend):
    """An isolated block (no gravity, the walls beyond h) with random velocities: artificial viscosity
    (Pi_ij symmetric, grad W antisymmetric), Verlet and the adaptive dt keep the total momentum to
    float32 round-off."""
    blob = {"domain": {"box_min": [0.0, 0.0], "box_max": [1.0, 1.0]}, "forces": {"gravity": [0.0, 0.0]},
            "fluid": {"spacing": 0.02, "blocks": [{"min": [0.35, 0.35], "max": [0.65, 0.65]}]}}
    scene = scene_of(COLUMN, MODELS, blob)
    state, params, stages, spec = scene_state(scene, jitter=0.3, seed=5)
    state["particle_v"][:, :2] = np.random.default_rng(6).normal(0, 0.5, (len(state["particle_v"]), 2))
    p0 = state["particle_v"][:, :2].astype(np.float64).sum(axis=0)
    sim = open_backend(backend, params, state, stages, spec)
    sim.step(100)
    s = particles(sim, 2)
    assert (np.abs(s["particle_x"] - 0.5) < 0.5 - scene.h).all(), "the block reached a wall"
    p1 = s["particle_v"].astype(np.float64).sum(axis=0)
    # 225 particles at ~0.5 m/s, float32 sums of ~10 terms per particle, 100 steps: ~1e-4
    np.testing.assert_allclose(p1, p0, atol=1e-3)
    speed = np.abs(s["particle_v"] - s["particle_v"].mean(axis=0)).max()
    assert speed > 1e-2, "nothing moved: the test would not see a violation"


def slide(wall_model, obstacle):
    """A layer of fluid (no gravity) sliding at 1 m/s along the floor, or along an obstacle's top."""
    floor = 0.2 if obstacle else 0.0
    return Scene.from_dict({
        "physics": {"model": "graphics"},
        "domain": {"box_min": [0.0, 0.0], "box_max": [1.0, 0.5], "wall_model": wall_model,
                   "obstacles": [{"min": [0.0, 0.0], "max": [1.0, floor]}] if obstacle else []},
        "fluid": {"spacing": 0.02, "blocks": [{"min": [0.2, floor], "max": [0.8, floor + 0.1]}], "viscosity": 1.0},
        "forces": {"gravity": [0.0, 0.0]}})


@pytest.mark.parametrize("obstacle", [False, True], ids=["floor", "obstacle"])
def test_no_slip_walls_drag_the_fluid_and_free_slip_walls_do_not(open_backend, obstacle):
    """Laminar viscosity on a uniform flow along a wall: free-slip images move with the fluid (no
    viscous force); no-slip images move against it, and the particles within h of the wall (or of
    an obstacle's face) are dragged back, the others not. (Vulkan only: the mirrors of every stage
    agree with it in test_each_stage_agrees_between_backends.)"""
    vulkan_or_skip()
    ax = {}
    for wall_model in ("free_slip", "no_slip"):
        scene = slide(wall_model, obstacle)
        x = scene.initial_positions()
        params = scene.params(len(x))
        state = empty_state(params, obstacles=scene["domain.obstacles"])
        state["particle_x"][:, :2] = x
        state["particle_v"][:, 0] = 1.0
        backend = open_backend("vulkan", params, state, plan(scene)[:-1], scene.spec)  # up to the forces
        backend.step(1)
        s = particles(backend, 2)
        ax[wall_model] = s["particle_a"][:, 0], s["particle_x"][:, 1] - (0.2 if obstacle else 0.0)
    a_free, _ = ax["free_slip"]
    a_no, height = ax["no_slip"]
    near = height < 0.5 * slide("no_slip", obstacle).h  # the row at dx / 2; the next, at 1.5 dx, sees images at h
    # free slip: no viscous force on the uniform flow; what is left is pressure at the layer's two ends
    # (measured 0.007 m/s^2), the same in both models (the same positions)
    assert np.abs(a_free).max() < 0.05, "free slip: the uniform flow feels no viscous force"
    drag = a_no - a_free
    assert (drag[near] < -1.0).all(), f"no slip: the layer at the wall is dragged back: {drag[near]}"
    assert np.abs(drag[~near]).max() < 1e-3  # (images exactly at h, to float32 rounding of the face at 0.2)


def energy_after(scene, dt, integrator, t_end):
    with Simulation(scene_of(scene.config, {"time": {"dt": dt, "integrator": integrator}})) as sim:
        sim.step(round(t_end / dt))
        s = sim.read()
        return s["particle_x"].astype(np.float64), sum(sim.energy(s))


def test_verlet_is_second_order_and_symplectic_euler_first():
    """A sloshing tank (a step in the free surface, laminar viscosity): the positions and the energy
    after 0.02 s at dt, dt / 2 against dt / 8 (Verlet). Halving dt divides symplectic Euler's errors by
    about 2 and Verlet's by about 4, and Verlet's energy at dt is the closer one."""
    tank = Scene.from_dict({
        "physics": {"model": "graphics", "precision": "float64"},  # float32 round-off (~1e-7 m) would hide Verlet's error at dt / 2
        "domain": {"box_min": [0.0, 0.0], "box_max": [0.6, 0.4]},
        "fluid": {"spacing": 0.02, "viscosity": 0.5,
                  "blocks": [{"min": [0.0, 0.0], "max": [0.3, 0.3]}, {"min": [0.3, 0.0], "max": [0.6, 0.14]}]}})
    dt, t_end = 4e-4, 0.02
    x_ref, e_ref = energy_after(tank, dt / 8, "verlet", t_end)
    errors = {}
    for integrator in ("symplectic_euler", "verlet"):
        runs = [energy_after(tank, d, integrator, t_end) for d in (dt, dt / 2)]
        errors[integrator] = [(np.abs(x - x_ref).max(), abs(e - e_ref)) for x, e in runs]
    (se1, se_e1), (se2, _) = errors["symplectic_euler"]
    (v1, v_e1), (v2, _) = errors["verlet"]
    assert 1.5 < se1 / se2 < 2.7, errors
    assert v1 / v2 > 3.0, errors
    assert v1 < se1 / 3 and v_e1 < se_e1, errors


RESUME = {"name": "dam", "fluid": {"spacing": 0.05, "blocks": [{"min": [0.0, 0.0], "max": [0.4, 0.6]}]},
          "time": {"steps": 150, "output_every": 20, "checkpoint_every": 50}}


def files(out_dir):
    return {p.name: p.read_bytes() for p in sorted(out_dir.iterdir())}


@pytest.mark.parametrize("backend, density", [("numba", "summation"), ("vulkan", "summation"),
                                              ("vulkan", "continuity")])
def test_resume_with_adaptive_dt_reaches_the_same_bits(backend, density, tmp_path):
    """The device's dt and time are state (time_state in CARRIED): a run stopped at step 110 and
    resumed gives final.npz (its time and dt included), the snapshots and the checkpoint of a run
    never stopped, byte for byte; with the continuity density too (its density is state), on Vulkan
    (the numba mirrors' agreement with it is tested stage by stage)."""
    if backend == "vulkan":
        vulkan_or_skip()
    scene = scene_of(RESUME, MODELS, {"physics": {"density": density}})
    assert {"time_state", "particle_vh"} <= set(CARRIED)
    run(scene, backend, 150, tmp_path / "whole", progress=False)
    run(scene, backend, 110, tmp_path / "resumed", progress=False)
    resume(tmp_path / "resumed", steps=150, progress=False)
    whole, resumed = files(tmp_path / "whole"), files(tmp_path / "resumed")
    for name in ("final.npz", CHECKPOINT, "dam_0000140.vtp", "dam_0000150.vtp"):
        assert resumed[name] == whole[name], name
    final = np.load(tmp_path / "whole" / "final.npz")
    state = np.load(tmp_path / "whole" / CHECKPOINT)["buffer_time_state"][0]
    assert final["dt"] == state[0] and final["time"] == float(state[2]) + float(state[3])
    assert 0 < final["dt"] < 0.25 * scene.h / 20.0  # the CFL bound at rest, c = 20 m/s
