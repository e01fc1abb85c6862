"""Kernels against analytic integrals, and the numba mirrors against a float64 all-pairs reference."""
import math

import numpy as np
import pytest
import reference

from sphcore.params import kernel_coefficients, lattice_mass
from sphcore.scene import Scene
from sphcore.simulation import Simulation


def radial_integral(f, h, n=200_000):
    r = (np.arange(n) + 0.5) * h / n
    return np.sum(2 * math.pi * r * f(r)) * h / n


@pytest.mark.parametrize("h", [0.01, 0.025, 1.0])
def test_2d_kernels_integrate_to_one(h):
    c = kernel_coefficients(h)
    assert radial_integral(lambda r: c["poly6"] * (h * h - r * r) ** 3, h) == pytest.approx(1.0, rel=1e-6)
    # the spiky kernel W = -c/3 (h - r)^3 has gradient c (h - r)^2: integrate W itself
    assert radial_integral(lambda r: -c["spiky_grad"] / 3 * (h - r) ** 3, h) == pytest.approx(1.0, rel=1e-6)
    # viscosity Laplacian: positive, vanishing at r = h
    assert c["visc_lap"] > 0 and c["visc_lap"] * (h - h) == 0


def small_scene(**fluid):
    return Scene.from_dict({
        "domain": {"box_min": [0.0, 0.0], "box_max": [0.3, 0.3]},
        "fluid": {"blocks": [{"min": [0.0, 0.0], "max": [0.16, 0.2]}], "spacing": 0.02, **fluid},
        "forces": {"gravity": [0.5, -9.81]},
    })


def test_lattice_interior_density_is_rest_density():
    scene = Scene.from_dict({"domain": {"box_min": [0, 0], "box_max": [1, 1]},
                             "fluid": {"blocks": [{"min": [0.2, 0.2], "max": [0.6, 0.6]}], "spacing": 0.02}})
    sim = Simulation(scene, "numba")
    sim.backend.run_stage("compute_density")
    state = sim.backend.read()
    x = state["particle_x"]
    interior = ((x > 0.2 + scene.h) & (x < 0.6 - scene.h)).all(axis=1)
    assert interior.sum() > 50
    # float32 sums of ~12 terms: relative rounding well below 1e-5
    np.testing.assert_allclose(state["particle_rho"][interior], 1000.0, rtol=1e-5)
    assert lattice_mass(0.02, scene.h, 1000.0) == pytest.approx(scene.mass)


def jittered(scene, seed=1):
    sim = Simulation(scene, "numba")
    rng = np.random.default_rng(seed)
    x = sim.backend.state["particle_x"]
    x += rng.uniform(-0.3, 0.3, x.shape).astype(np.float32) * scene["fluid.spacing"]
    np.clip(x, 0.0, 0.3, out=x)
    x[0] = x[1]  # two coincident particles
    x[2] = (0.0, 0.0)  # a particle in the corner
    sim.backend.state["particle_v"][:] = rng.normal(0, 0.5, x.shape).astype(np.float32)
    return sim


def test_density_and_pressure_match_float64_reference():
    scene = small_scene()
    sim = jittered(scene)
    sim.backend.run_stage("compute_density")
    s = sim.backend.read()
    rho, p = reference.density_pressure(s["particle_x"].astype(np.float64), scene.mass, scene.h, 1000.0,
                                        scene["fluid.stiffness"], np.array([0.0, 0.0]), np.array([0.3, 0.3]))
    # float32 against float64: (h^2 - r^2)^3 loses ~1e-6 relative per term, summed over ~10 terms
    np.testing.assert_allclose(s["particle_rho"], rho, rtol=2e-5)
    # p = k (rho - rho_0) amplifies the density's absolute error by k
    np.testing.assert_allclose(s["particle_p"], p, atol=scene["fluid.stiffness"] * 1000.0 * 2e-5)


def test_acceleration_matches_float64_reference():
    scene = small_scene(viscosity=5.0)
    sim = jittered(scene)
    sim.backend.run_stage("compute_density")
    sim.backend.run_stage("compute_forces")
    s = sim.backend.read()
    x = s["particle_x"].astype(np.float64)
    a = reference.acceleration(x, s["particle_v"].astype(np.float64), s["particle_rho"].astype(np.float64),
                               s["particle_p"].astype(np.float64), scene.mass, scene.h, 5.0,
                               np.array(scene["forces.gravity"]), np.array([0.0, 0.0]), np.array([0.3, 0.3]))
    scale = np.abs(a).max()
    # float32 sums of terms that cancel (pressure from all sides): error relative to the largest acceleration
    np.testing.assert_allclose(s["particle_a"], a, atol=2e-5 * scale)
    assert np.isfinite(s["particle_a"]).all()
    # the coincident pair is pushed apart, in opposite directions along x
    assert s["particle_a"][0, 0] * s["particle_a"][1, 0] < 0
