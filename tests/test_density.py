"""Issue 12, density and kernels: Wendland C2 against analytic integrals, continuity density and
density diffusion (Molteni & Colagrossi 2009, Fourtakas et al. 2019) on both backends, momentum,
rest, resume, and the scene keys."""
import math

import numpy as np
import pytest
from conftest import BACKENDS, assert_stage_agrees, particles, scene_state, vulkan_or_skip  # noqa: F401

from sphcore.backends import Stage, in_particle_order, make_backend, plan
from sphcore.params import PARAMS_DTYPE, Spec, kernel_coefficients, lattice_mass
from sphcore.scene import Scene, SceneError
from sphcore.simulation import Simulation
from sphcore.sph.kernels import kernels

KERNELS = ["mueller", "wendland_c2"]


def kernel_functions(kernel, dim, h):
    """(W(r), grad W(r) . r_hat, L(r)) of kernels.glsl's mirror in float64, coefficients folded as the host does."""
    P = np.zeros(1, PARAMS_DTYPE)
    P[0]["h"], P[0]["h2"] = h, h * h
    helpers = kernels(Spec(DIM=dim, KERNEL=KERNELS.index(kernel)), np.float64)
    kernel_w, kernel_gradient, kernel_laplacian = helpers.kernel_w, helpers.kernel_gradient, helpers.kernel_laplacian
    c = kernel_coefficients(h, dim, kernel)
    h32 = float(np.float32(h))  # the parameter block is float32: the helpers see h rounded
    rec = P[0]
    w = np.vectorize(lambda r: c["w"] * kernel_w(rec, r * r))
    dw = np.vectorize(lambda r: -c["gradient"] * kernel_gradient(rec, r * r, r))
    lap = np.vectorize(lambda r: c["laplacian"] * kernel_laplacian(rec, r * r, r))
    return w, dw, lap, h32


def radial(f, h, dim, n=20_000):
    r = (np.arange(n) + 0.5) * h / n
    shell = 2 * math.pi * r if dim == 2 else 4 * math.pi * r * r
    return float(np.sum(shell * f(r)) * h / n)


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("kernel", KERNELS)
def test_kernel_integrals(kernel, dim):
    """integral W = 1; integral r . grad W = -dim (divergence theorem: W vanishes at the support);
    the gradient is W's derivative (central differences); the Laplacian is positive and vanishes at h."""
    h = 0.04
    w, dw, lap, h32 = kernel_functions(kernel, dim, h)
    if kernel == "wendland_c2":  # normalised to integrate to one (Mueller's spiky is not poly6's derivative)
        assert radial(w, h32, dim) == pytest.approx(1.0, rel=2e-6)
        assert radial(lambda r: r * dw(r), h32, dim) == pytest.approx(-dim, rel=2e-6)
        r = np.linspace(0.05, 0.95, 19) * h32
        eps = 1e-7
        np.testing.assert_allclose(dw(r), (w(r + eps) - w(r - eps)) / (2 * eps), rtol=1e-5)
        assert dw(np.array([0.0]))[0] == 0.0  # smooth at r = 0: coincident particles feel nothing
    else:
        assert radial(w, h32, dim) == pytest.approx(1.0, rel=2e-6)
        spiky = -kernel_coefficients(h, dim)["spiky_grad"] / 3
        assert radial(lambda r: spiky * (h32 - r) ** 3, h32, dim) == pytest.approx(1.0, rel=1e-5)
        assert radial(lambda r: r * dw(r), h32, dim) == pytest.approx(-dim, rel=1e-5)
    r = np.linspace(0.01, 0.99, 50) * h32
    assert (lap(r) > 0).all() and abs(lap(np.array([h32]))[0]) < 1e-9 * lap(r).max()


def test_wendland_lattice_sums_to_rest_density():
    """The lattice mass uses the scene's kernel: a full lattice sums to rho_0 (2D through the shaders'
    mirror; 3D through kernels.glsl's mirror in float32, the shaders' precision)."""
    scene = Scene.from_dict({"physics": {"model": "graphics", "kernel": "wendland_c2"}, "domain": {"box_min": [0, 0], "box_max": [0.3, 0.3]},
                             "fluid": {"blocks": [{"min": [0.0, 0.0], "max": [0.16, 0.2]}], "spacing": 0.02}})
    sim = Simulation(scene, "numba")
    state = in_particle_order(sim.backend.read(), 2)
    x = state["particle_x"]
    interior = ((x > scene.h) & (x < [0.16 - scene.h, 0.2 - scene.h])).all(axis=1)
    assert interior.sum() >= 8
    np.testing.assert_allclose(state["particle_rho"][interior], 1000.0, rtol=1e-5)
    assert scene.mass == pytest.approx(lattice_mass(0.02, scene.h, 1000.0, 2, "wendland_c2"))
    assert scene.mass != pytest.approx(lattice_mass(0.02, scene.h, 1000.0, 2), rel=1e-3)
    # 3D: sum m W over a cubic lattice around a particle, in float32 as compute_density does
    scene3 = Scene.from_dict({"physics": {"model": "graphics", "dimension": 3, "kernel": "wendland_c2"},
                              "fluid": {"blocks": [{"min": [0.0] * 3, "max": [0.2] * 3}], "spacing": 0.04}})
    params = scene3.params(1)
    kernel_w = kernels(scene3.spec, np.float32).kernel_w
    k = np.arange(-2, 3) * 0.04
    r2 = (sum(np.meshgrid(k ** 2, k ** 2, k ** 2, indexing="ij"))).ravel().astype(np.float32)
    total = np.float32(0.0)
    for q in r2[r2 < np.float32(params[0]["h2"])]:
        total += kernel_w(params[0], q)
    assert float(params[0]["density_coef"] * total) == pytest.approx(1000.0, rel=1e-5)


def small(dim=2, kernel="wendland_c2", density="continuity", diffusion="fourtakas", **extra):
    physics = {"model": "graphics", "dimension": dim, "kernel": kernel, "density": density, "density_diffusion": diffusion,
               **extra.pop("physics", {})}
    return Scene.from_dict({
        "physics": physics,
        "domain": {"box_min": [0.0] * dim, "box_max": [0.3] * dim, **extra.pop("domain", {})},
        "fluid": {"blocks": [{"min": [0.0] * dim, "max": [0.16, 0.2, 0.1][:dim]}], "spacing": 0.02},
        "time": {"dt": 2e-4}, **extra})


# One dispatch of every stage from the same jittered, moving state (see test_backends.STAGE_RTOL): the
# density's rate sums terms of both signs, so its error is relative to its largest magnitude.
# Two specs (each costs numba ~40 s to compile on 2 cores): Wendland with continuity and Fourtakas' diffusion
# (shared with the rest and resume tests), Wendland with summation (shared with the lattice test). Mueller's
# kernels with continuity and Molteni's diffusion run in the momentum test (numba).
STAGE_CASES = [dict(dim=2, kernel="wendland_c2", diffusion="fourtakas"),
               dict(dim=2, kernel="wendland_c2", density="summation", diffusion="none")]


@pytest.mark.parametrize("case", STAGE_CASES, ids=lambda c: "-".join(map(str, c.values())))
def test_each_stage_agrees_between_backends(open_backend, case):
    scene = small(**case)
    state, params, stages, spec = scene_state(scene, jitter=0.3, seed=5)
    rng = np.random.default_rng(6)
    state["particle_v"][:, :scene.dim] = rng.normal(0, 1, (len(state["particle_v"]), scene.dim))
    state["particle_rho"][:] *= rng.uniform(0.99, 1.01, len(state["particle_rho"])).astype(np.float32)
    if spec.CONTINUITY:
        assert "integrate_density" in [s.name for s in stages]
    cpu = open_backend("numba", params, state, stages, spec)
    gpu = open_backend("vulkan", params, state, stages, spec)
    for stage in stages:
        cpu.run_stage(stage)
        gpu.run_stage(stage)
        assert_stage_agrees(cpu.read(), gpu.read(), stage, 2e-5)
    cpu.step(20)
    gpu.step(20)
    a, b = particles(cpu, scene.dim), particles(gpu, scene.dim)
    assert np.abs(a["particle_x"] - b["particle_x"]).max() < 1e-4 * scene["fluid.spacing"]
    assert np.abs(a["particle_rho"] - b["particle_rho"]).max() < 1e-3


def test_plan_has_integrate_density_only_with_continuity():
    names = lambda scene: [s.name for s in plan(scene)]  # noqa: E731
    assert "integrate_density" not in names(small(density="summation", diffusion="none"))
    stages = names(small())
    assert stages.index("compute_density") < stages.index("integrate_density") < stages.index("compute_forces")


def test_momentum_of_an_isolated_block_stays_zero():
    """No gravity, no walls: pressure, viscosity and density diffusion act in pairs, so the total momentum
    stays at its start (zero) to float32 round-off; and a block at rest there stays exactly at rest."""
    scene = small(kernel="mueller", diffusion="molteni", physics={"gravity": False},
                  domain={"boundary": "open", "box_min": [-0.3, -0.3], "box_max": [0.5, 0.5]})
    sim = Simulation(scene, "numba")
    rng = np.random.default_rng(2)
    v = rng.normal(0, 0.5, (sim.n, 2)).astype(np.float32)
    v -= v.mean(axis=0)
    sim.backend.state["particle_v"][:, :2] = v
    sim.advance(60)
    s = sim.read()
    momentum = np.abs(s["particle_v"].astype(np.float64).sum(axis=0)).max()
    assert momentum < 1e-5 * np.abs(v).sum()
    assert np.abs(s["particle_v"] - v).max() > 0.01  # the forces acted
    rest = Simulation(scene, "numba")
    rest.advance(20)
    s = rest.read()
    assert np.abs(s["particle_v"]).max() == 0.0 and (s["particle_rho"] == 1000.0).all()


def test_continuity_block_at_rest_stays_at_rest():
    """A hydrostatic tank (continuity density, starting hydrostatic): Fourtakas' diffusion term vanishes
    on it (Molteni's does not: it pulls the column towards uniform density), and the tank stays still."""
    tank = {"domain": {"box_min": [0.0, 0.0], "box_max": [0.2, 0.4]},
            "fluid": {"blocks": [{"min": [0.0, 0.0], "max": [0.2, 0.3]}], "spacing": 0.02}, "time": {"dt": "auto"}}
    scene = Scene.from_dict({"physics": {"model": "graphics", "density": "continuity", "density_diffusion": "fourtakas",
                                         "kernel": "wendland_c2"}, **tank})
    sim = Simulation(scene, "numba")
    rates = {"fourtakas": np.abs(sim.backend.state["particle_drho"]).max()}
    # Molteni's term is Fourtakas' without the hydrostatic part: the same shader with P.hydrostatic = 0
    state, params, stages, spec = scene_state(scene)
    params[0]["hydrostatic"] = 0.0
    molteni = make_backend("numba", params, state, stages, spec)
    for stage in stages[:stages.index(Stage("compute_density")) + 1]:
        molteni.run_stage(stage)
    rates["molteni"] = np.abs(molteni.state["particle_drho"]).max()
    sim.advance(200)
    s = sim.read()
    # free fall over the same time would be g t = 0.8 m/s; the summation model moves ~0.1 m/s here
    assert np.abs(s["particle_v"]).max() < 0.03
    assert rates["fourtakas"] < 1e-3 * rates["molteni"]


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_wall_pushes_off_a_particle_pressed_onto_it(open_backend, backend):
    """The engineering model (Wendland C2 on 4 dx, continuity) in a tank at rest, one particle of the bottom
    row put 0.02 dx above the floor. Its own image is then 0.04 dx away, where Wendland's gradient is
    almost zero, and its neighbours' images balance it: without the held gradient of kernels.glsl's
    pair_gradient it stayed on the floor and the whole bottom row followed it there (measured: 18 of 20
    particles at y = 0 by t = 0.19 s). The wall must push it back up and keep every particle off it."""
    from sphcore.validate import configs

    dx = 0.01
    data = {"physics": {"model": "graphics", "dimension": 2, "equation_of_state": "linear"},
            "domain": {"box_min": [0.0, 0.0], "box_max": [0.2, 0.4]},
            "fluid": {"blocks": [{"min": [0.0, 0.0], "max": [0.2, 0.1]}], "spacing": dx, "stiffness": 400.0},
            "time": {"dt": "auto"}}
    scene = Scene.from_dict(configs.apply(data, configs.ENGINEERING))
    state, params, stages, spec = scene_state(scene)
    x = state["particle_x"]
    k = int(np.argmin(np.abs(x[:, 0] - 0.105) + np.abs(x[:, 1] - 0.005)))
    x[k, 1] = 0.02 * dx
    sim = open_backend(backend, params, state, stages, spec)
    lowest = []
    for _ in range(4):
        sim.step(150)
        y = particles(sim, 2)["particle_x"][:, 1]
        lowest.append(y.min())
        assert y[k] > 0.2 * dx  # pushed back up (measured 0.32-0.36 dx)
    assert min(lowest) > 0.1 * dx  # no particle reached the floor (measured: the lowest at 0.15 dx)


def test_initial_density_is_hydrostatic():
    for eos in ("linear", "tait"):
        scene = Scene.from_dict({"physics": {"model": "graphics", "density": "continuity", "equation_of_state": eos},
                                 "fluid": {"blocks": [{"min": [0.0, 0.0], "max": [0.2, 0.4]}], "spacing": 0.02}})
        x = scene.initial_positions()
        rho = scene.initial_density(x)
        depth = 0.4 - x[:, 1]
        k = scene["fluid.stiffness"]
        pressure = k * (rho - 1000.0) if eos == "linear" else 1000.0 * k / 7 * ((rho / 1000.0) ** 7 - 1)
        np.testing.assert_allclose(pressure, 1000.0 * 9.81 * depth, rtol=1e-6)  # x is float32
    summation = Scene.from_dict({"physics": {"model": "graphics"}, "fluid": {"blocks": [{"min": [0.0, 0.0], "max": [0.2, 0.4]}], "spacing": 0.02}})
    assert (summation.initial_density(summation.initial_positions()) == 1000.0).all()


BAD = [({"physics": {"model": "graphics", "kernel": "cubic"}}, "physics.kernel"),
       ({"physics": {"model": "graphics", "density": "integral"}}, "physics.density"),
       ({"physics": {"model": "graphics", "density_diffusion": "antuono"}}, "physics.density_diffusion"),
       ({"physics": {"model": "graphics", "density_diffusion": "molteni"}}, "physics.density_diffusion"),
       ({"physics": {"model": "graphics", "density": "continuity"}, "fluid": {"density_diffusion": 2.0}}, "fluid.density_diffusion"),
       ({"physics": {"model": "graphics", "density": "continuity"}, "fluid": {"density_diffusion": "big"}}, "fluid.density_diffusion")]


@pytest.mark.parametrize("data, key", BAD, ids=[k for _, k in BAD])
def test_bad_values_are_rejected_naming_the_key(data, key):
    with pytest.raises(SceneError, match=key.replace(".", r"\.")):
        Scene.from_dict(data)


def test_diffusion_with_summation_names_both_keys():
    with pytest.raises(SceneError) as e:
        Scene.from_dict({"physics": {"model": "graphics", "density_diffusion": "fourtakas"}})
    assert "physics.density_diffusion" in str(e.value) and "physics.density" in str(e.value).replace(
        "physics.density_diffusion", "")


@pytest.mark.parametrize("backend", BACKENDS)
def test_resume_with_continuity_density_is_bitwise(backend, tmp_path):
    """The density is state: it travels with the grid's sort and goes into the checkpoint."""
    from sphcore.simulation import run
    if backend == "vulkan":
        vulkan_or_skip()
    data = {"name": "dam", "physics": {"model": "graphics", "density": "continuity", "density_diffusion": "fourtakas",
                                       "kernel": "wendland_c2"},
            "fluid": {"spacing": 0.05, "blocks": [{"min": [0.0, 0.0], "max": [0.4, 0.6]}]},
            "time": {"dt": 1e-3, "steps": 120, "output_every": 40, "checkpoint_every": 60}}
    whole, part = tmp_path / "whole", tmp_path / "part"
    run(Scene.from_dict(data), backend, 120, whole, progress=False)
    run(Scene.from_dict(data), backend, 60, part, progress=False)
    from sphcore.cli import main
    assert main(["run", "--resume", str(part), "--steps", "120"]) == 0
    assert (part / "final.npz").read_bytes() == (whole / "final.npz").read_bytes()
    density = np.load(whole / "final.npz")["density"]
    assert density.std() > 0.1  # the density is the integrated state, not rho_0
