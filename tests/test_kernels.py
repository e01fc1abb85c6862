"""Kernels against analytic integrals, and the numba mirrors against a float64 all-pairs reference."""
import math

import numpy as np
import pytest
import reference

from sphcore.params import kernel_coefficients, lattice_mass
from sphcore.scene import Scene
from sphcore.backends import in_particle_order
from sphcore.simulation import Simulation


def radial_integral(f, h, dim, n=200_000):
    r = (np.arange(n) + 0.5) * h / n
    shell = 2 * math.pi * r if dim == 2 else 4 * math.pi * r * r
    return np.sum(shell * f(r)) * h / n


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("h", [0.01, 0.025, 1.0])
def test_kernels_integrate_to_one(h, dim):
    c = kernel_coefficients(h, dim)
    assert radial_integral(lambda r: c["poly6"] * (h * h - r * r) ** 3, h, dim) == pytest.approx(1.0, rel=1e-6)
    # the spiky kernel W = -c/3 (h - r)^3 has gradient c (h - r)^2: integrate W itself
    assert radial_integral(lambda r: -c["spiky_grad"] / 3 * (h - r) ** 3, h, dim) == pytest.approx(1.0, rel=1e-6)
    # viscosity Laplacian: positive, vanishing at r = h
    assert c["visc_lap"] > 0 and c["visc_lap"] * (h - h) == 0


def small_scene(dim=2, search="grid", tait=False, cohesion=0.0, **fluid):
    box = [0.3] * dim
    return Scene.from_dict({
        "physics": {"model": "graphics", "dimension": dim, "neighbour_search": search, "surface_tension": cohesion > 0,
                    "equation_of_state": "tait" if tait else "linear"},
        "domain": {"box_min": [0.0] * dim, "box_max": box},
        "fluid": {"blocks": [{"min": [0.0] * dim, "max": [0.16, 0.2, 0.1][:dim]}], "spacing": 0.02,
                  "cohesion": cohesion, **fluid},
        "forces": {"gravity": [0.5, -9.81, 0.2][:dim]},
    })


@pytest.mark.parametrize("dim", [2, 3])
def test_lattice_interior_density_is_rest_density(dim):
    scene = Scene.from_dict({"physics": {"model": "graphics", "dimension": dim}, "domain": {"box_min": [0] * dim, "box_max": [1] * dim},
                             "fluid": {"blocks": [{"min": [0.2] * dim, "max": [0.6] * dim}], "spacing": 0.04}})
    sim = Simulation(scene, "numba")
    run_until(sim, "compute_density")
    state = in_particle_order(sim.backend.read(), dim)
    x = state["particle_x"]
    interior = ((x > 0.2 + scene.h) & (x < 0.6 - scene.h)).all(axis=1)
    assert interior.sum() >= 8
    # float32 sums of ~12 (2D) to ~30 (3D) terms: relative rounding well below 1e-5
    np.testing.assert_allclose(state["particle_rho"][interior], 1000.0, rtol=1e-5)
    assert lattice_mass(0.04, scene.h, 1000.0, dim) == pytest.approx(scene.mass)


def run_until(sim, last):
    """Run the plan's stages of one step up to and including `last` (the grid's sort first)."""
    for stage in sim.stages:
        sim.backend.run_stage(stage)
        if stage.name == last:
            return


def jittered(scene, seed=1):
    sim = Simulation(scene, "numba")
    rng = np.random.default_rng(seed)
    dim = scene.dim
    x = sim.backend.state["particle_x"][:, :dim]
    x += rng.uniform(-0.3, 0.3, x.shape).astype(np.float32) * scene["fluid.spacing"]
    np.clip(x, 0.0, 0.3, out=x)
    x[0] = x[1]  # two coincident particles
    x[2] = 0.0  # a particle in the corner
    sim.backend.state["particle_v"][:, :dim] = rng.normal(0, 0.5, x.shape).astype(np.float32)
    return sim


CASES = [dict(dim=2, search="all_pairs"), dict(dim=2, search="grid"), dict(dim=3, search="grid"),
         dict(dim=3, search="all_pairs", tait=True), dict(dim=2, search="grid", tait=True, cohesion=0.3),
         dict(dim=3, search="grid", cohesion=0.05)]


def case_id(case):
    return "-".join(f"{k}={v}" for k, v in case.items())


@pytest.mark.parametrize("case", CASES, ids=case_id)
def test_density_and_pressure_match_float64_reference(case):
    scene = small_scene(**case)
    sim = jittered(scene)
    run_until(sim, "compute_density")
    s = sim.backend.read()
    dim = scene.dim
    rho, p = reference.density_pressure(s["particle_x"][:, :dim].astype(np.float64), scene.mass, scene.h, 1000.0,
                                        scene["fluid.stiffness"], np.zeros(dim), np.full(dim, 0.3),
                                        tait=case.get("tait", False))
    # float32 against float64: (h^2 - r^2)^3 loses ~1e-6 relative per term, summed over ~10-40 terms
    np.testing.assert_allclose(s["particle_rho"], rho, rtol=2e-5)
    # the equation of state amplifies the density's absolute error by dp/drho = k (7 k for Tait at 1.0x)
    np.testing.assert_allclose(s["particle_p"], p, atol=scene["fluid.stiffness"] * 1000.0 * 2e-5 * 1.5)


@pytest.mark.parametrize("case", CASES, ids=case_id)
def test_acceleration_matches_float64_reference(case):
    scene = small_scene(viscosity=5.0, **case)
    sim = jittered(scene)
    run_until(sim, "compute_forces")
    s = sim.backend.read()
    dim = scene.dim
    x = s["particle_x"][:, :dim].astype(np.float64)
    a = reference.acceleration(x, s["particle_v"][:, :dim].astype(np.float64), s["particle_rho"].astype(np.float64),
                               s["particle_p"].astype(np.float64), scene.mass, scene.h, 5.0,
                               np.array(scene["forces.gravity"]), np.zeros(dim), np.full(dim, 0.3),
                               cohesion=case.get("cohesion", 0.0))
    scale = np.abs(a).max()
    # float32 sums of terms that cancel (pressure from all sides): error relative to the largest acceleration
    np.testing.assert_allclose(s["particle_a"][:, :dim], a, atol=2e-5 * scale)
    assert np.isfinite(s["particle_a"]).all()
    # the coincident pair (ids 0 and 1) is pushed apart, in opposite directions along x
    first, second = (np.flatnonzero(s["particle_id"] == k)[0] for k in (0, 1))
    assert s["particle_a"][first, 0] * s["particle_a"][second, 0] < 0
