"""Scenes against physics: a column at rest, conservation, extremes."""
import numpy as np
import pytest
from conftest import BACKENDS, particles, scene_state

from sphcore.cli import scene_path
from sphcore.scene import Scene

G = 9.81


def tank(dim):
    """The shipped tank scenes; the 3D one cut to 8 x 12 x 8 particles to keep the test short."""
    scene = Scene.load(scene_path(f"tank_{dim}d"))
    if dim == 3:
        scene = Scene.from_dict({**scene.config, "domain": {"box_min": [0, 0, 0], "box_max": [0.08, 0.24, 0.08]},
                                 "fluid": {**scene.config["fluid"], "blocks": [{"min": [0, 0, 0], "max": [0.08, 0.12, 0.08]}]}})
    return scene


def window_slope(sim, scene, steps, every=50):
    """dp/d(depth) fitted to every (depth, p) sample of the interior over `steps` steps, and the
    largest speed and density deviation seen. Pooling over many sound-crossing times averages
    out the tank's acoustic oscillation (period 4 H / c = 0.03 s), which dominates any one snapshot."""
    depths, pressures, speed, drho = [], [], 0.0, 0.0
    for _ in range(steps // every):
        sim.step(every)
        s = particles(sim, scene.dim)
        y, p = s["particle_x"][:, 1], s["particle_p"]
        surface = np.sort(y)[-20:].mean()
        interior = (y > 2 * scene.h) & (surface - y > 2 * scene.h)
        depths.append(surface - y[interior])
        pressures.append(p[interior])
        speed = max(speed, float(np.abs(s["particle_v"]).max()))
        drho = max(drho, float(np.abs(s["particle_rho"][interior] / 1000.0 - 1).max()))
    slope = np.polyfit(np.concatenate(depths), np.concatenate(pressures), 1)[0]
    return slope / (1000.0 * G), speed, drho


# (dim, backend): 3D runs on numba only; lavapipe takes ~30 steps/s there, and the backends'
# agreement in 3D is tested step by step in test_backends.
TANKS = [(2, "numba"), (2, "vulkan"), (3, "numba")]


@pytest.mark.parametrize("dim,backend", TANKS)
def test_tank_at_rest_is_hydrostatic_and_stays_so(open_backend, dim, backend):
    scene = tank(dim)
    state, params, stages, spec = scene_state(scene)
    sim = open_backend(backend, params, state, stages, spec)
    # 0.3 s (2D) or 0.55 s (3D): ten or more sound crossings of the 0.12-0.2 m column, viscous settling
    # (the graphics model's column mode is barely damped: in 3D its slope was 1.29 rho g over
    # 0.3-0.55 s after a change of rounding in the pressure term, 1.15 after)
    sim.step(3000 if dim == 2 else 5500)
    first, speed1, drho1 = window_slope(sim, scene, 2500)
    second, speed2, drho2 = window_slope(sim, scene, 2500)
    # Pressure grows as rho g depth. Measured: 1.1-1.2 rho g in 2D and 3D at h = 2 dx with
    # mirror-wall boundaries (the spiky-gradient pressure force with ~12 (2D) to ~30 (3D)
    # neighbours is not exactly consistent). Stated tolerance: within 25 %.
    for slope in (first, second):
        assert 0.75 < slope < 1.25, f"dp/d(depth) = {slope:.3f} rho g (windows {first:.3f}, {second:.3f})"
    # ... and stays there: the two windows agree, nothing flows, and the interior density stays
    # within 5 % of rho_0 in every sample (measured: up to 3.3 % in 3D at 0.3-0.55 s, 1.1 % later:
    # the acoustic oscillation, weakly damped by viscosity alone)
    assert abs(second - first) < 0.1, f"slope drifted from {first:.3f} to {second:.3f} rho g"
    assert max(speed1, speed2) < 0.1, f"the tank is not at rest: {max(speed1, speed2):.3f} m/s"
    assert max(drho1, drho2) < 0.05, f"density off rho_0 by {max(drho1, drho2):.1%}"
    assert drho2 <= drho1 + 0.005, "the oscillation grows"


def zero_gravity_blob(**fluid):
    return Scene.from_dict({
        "physics": {"model": "graphics"},
        "domain": {"box_min": [0.0, 0.0], "box_max": [1.0, 1.0]},
        "fluid": {"blocks": [{"min": [0.4, 0.4], "max": [0.6, 0.6]}], "spacing": 0.01, **fluid},
        "forces": {"gravity": [0.0, 0.0]},
    })


@pytest.mark.parametrize("backend", BACKENDS)
def test_momentum_is_conserved_away_from_walls(open_backend, backend):
    """Pressure and viscosity forces are antisymmetric in (i, j): total momentum stays constant."""
    scene = zero_gravity_blob(viscosity=2.0)
    state, params, stages, spec = scene_state(scene, jitter=0.4, seed=5)
    rng = np.random.default_rng(6)
    state["particle_v"][:, :2] = rng.normal(0, 0.2, (len(state["particle_v"]), 2))
    p0 = state["particle_v"][:, :2].astype(np.float64).sum(axis=0)
    sim = open_backend(backend, params, state, stages, spec)
    sim.step(200)
    s = particles(sim, 2)
    assert (np.abs(s["particle_x"] - 0.5) < 0.5 - scene.h).all(), "the blob reached a wall"
    p1 = s["particle_v"].astype(np.float64).sum(axis=0)
    # float32 velocities of ~0.2 m/s summed over 400 particles and 200 steps: rounding ~1e-4
    np.testing.assert_allclose(p1, p0, atol=2e-3)
    speed = np.abs(s["particle_v"] - s["particle_v"].mean(axis=0)).max()
    assert speed > 1e-3, "nothing moved: the test would not see a violation"


@pytest.mark.parametrize("backend", BACKENDS)
def test_walls_and_corners_are_handled_in_one_step(open_backend, backend):
    """A particle past a corner is put back on both walls and both normal speeds reversed in one
    step (seed 1's else-if chain handled one wall per step)."""
    from sphcore.backends import Stage, empty_state

    scene = zero_gravity_blob()
    corners = np.array([[0.001, 0.001], [0.999, 0.001], [0.001, 0.999], [0.999, 0.999], [0.5, 0.001]], np.float32)
    params = scene.params(len(corners))
    state = empty_state(params)
    state["particle_x"][:, :2] = corners
    state["particle_v"][:, :2] = 20.0 * np.sign(corners - 0.5)  # outward on both axes (x = 0.5: +x)
    sim = open_backend(backend, params, state, [Stage("integrate")], scene.spec)
    sim.step(1)
    s = particles(sim, 2)
    x, v = s["particle_x"], s["particle_v"]
    outward = np.sign(corners - 0.5)
    hit = np.abs(corners - 0.5) > 0.49  # the axes on which each particle crosses a wall
    np.testing.assert_array_equal(x[hit], np.where(outward[hit] > 0, 1.0, 0.0))
    np.testing.assert_allclose(v[hit], -scene["walls.restitution"] * 20.0 * outward[hit], rtol=1e-6)
    np.testing.assert_allclose(v[~hit], 20.0 * outward[~hit])


@pytest.mark.parametrize("backend", BACKENDS)
def test_particles_thrown_at_the_walls_stay_inside_and_finite(open_backend, backend):
    scene = zero_gravity_blob()
    state, params, stages, spec = scene_state(scene)
    direction = state["particle_x"][:, :2] - 0.5
    state["particle_v"][:, :2] = 40.0 * direction / np.linalg.norm(direction, axis=1, keepdims=True)
    sim = open_backend(backend, params, state, stages, spec)
    for _ in range(10):
        sim.step(20)
        s = particles(sim, 2)
        assert all(np.isfinite(v).all() for v in s.values())
        assert ((s["particle_x"] >= 0.0) & (s["particle_x"] <= 1.0)).all()
    assert (np.abs(s["particle_x"] - 0.5) > 0.5 - scene.h).any(), "no particle reached a wall"


def sphericity(x):
    """Largest over smallest extent of the blob along the 26 lattice directions (faces, edges,
    corners): a cube gives sqrt(3) = 1.73, a sphere 1. (The ratio of principal moments, often
    used, cannot see a cube turn into a sphere: a cube's moments are already isotropic.)"""
    import itertools
    d = np.array([v for v in itertools.product([-1, 0, 1], repeat=3) if any(v)], float)
    d /= np.linalg.norm(d, axis=1)[:, None]
    extent = ((x - x.mean(axis=0)) @ d.T).max(axis=0)
    return extent.max() / extent.min()


def test_zero_gravity_cube_becomes_round(open_backend):
    """Surface tension by cohesion pulls a cube of fluid into a sphere (seed 2's demonstration)."""
    scene = Scene.load(scene_path("droplet_3d"))
    scene = Scene.from_dict({**scene.config, "fluid": {**scene.config["fluid"], "cohesion": 0.004,
                                                        "blocks": [{"min": [0.11] * 3, "max": [0.19] * 3}]}})
    state, params, stages, spec = scene_state(scene)
    x0 = state["particle_x"][:, :3].copy()
    assert sphericity(x0) == pytest.approx(3**0.5, rel=0.01)
    sim = open_backend("numba", params, state, stages, spec)
    sim.step(2000)  # 0.4 s
    s = particles(sim, 3)
    # measured 1.08 at 0.4 s (1.73 at the start); momentum stays zero, so the blob does not drift
    assert sphericity(s["particle_x"]) < 1.15
    np.testing.assert_allclose(s["particle_x"].mean(axis=0), x0.mean(axis=0), atol=1e-4)
    assert np.isfinite(s["particle_v"]).all()


def test_without_surface_tension_the_cube_stays_square(open_backend):
    """The control: the same cube without cohesion keeps its corners (pressure only pushes out)."""
    scene = Scene.load(scene_path("droplet_3d"))
    scene = Scene.from_dict({**scene.config, "physics": {**scene.config["physics"], "surface_tension": False},
                             "fluid": {**scene.config["fluid"], "blocks": [{"min": [0.11] * 3, "max": [0.19] * 3}]}})
    state, params, stages, spec = scene_state(scene)
    sim = open_backend("numba", params, state, stages, spec)
    sim.step(2000)
    assert sphericity(particles(sim, 3)["particle_x"]) > 1.4


def test_a_particle_clamped_onto_a_wall_is_inside():
    """float32(1.2) > 1.2: the box check must compare with the walls the shaders use (float32)."""
    from sphcore.simulation import Simulation
    scene = Scene.from_dict({"physics": {"model": "graphics", "dimension": 3}, "domain": {"box_max": [1.2, 0.6, 0.3]},
                             "fluid": {"blocks": [{"min": [0.0, 0.0, 0.0], "max": [0.1, 0.1, 0.1]}], "spacing": 0.02}})
    sim = Simulation(scene, "numba")
    x = sim.backend.state["particle_x"]
    x[0, :3] = np.array([1.2, 0.6, 0.3], np.float32)
    assert float(x[0, 0]) > 1.2  # the premise
    x[1, :3] = 0.0
    sim.read()  # no SimulationError
    x[2, 0] = np.nextafter(np.float32(1.2), np.float32(2))
    with pytest.raises(Exception, match="left the box"):
        sim.read()
