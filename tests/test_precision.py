"""physics.precision = "float64": the shaders built with SPHCORE_FLOAT64 against their float64 numba
mirrors, the float64 build against a float64 reference, the output's dtypes, and a device
without shaderFloat64."""
import re
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from conftest import assert_stage_agrees, particles, vulkan_or_skip

from sphcore.backends import BUFFERS, REAL, Stage, buffer_dtype, empty_state, plan
from sphcore.cli import main, scene_path
from sphcore.params import SHADER_DIR
from sphcore.scene import Scene
from sphcore.simulation import run

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib


def cube_drop_2d(precision="float64"):
    """The 900-particle 2D demo scene (walls, linear EOS, viscosity, gravity) at `precision`."""
    data = tomllib.loads(scene_path("cube_drop_2d").read_text())
    data.setdefault("physics", {})["precision"] = precision
    return Scene.from_dict(data)


def corner_3d():
    """216 particles in the corner of a 3D tank (images across three walls), Tait, viscosity,
    cohesion, gravity: every term of the 3D build. All pairs: the float64 grid sort is the 2D
    case's (numba compiles each stage per spec and precision, ~20 s for the sort's stages)."""
    return Scene.from_dict({
        "name": "corner_3d",
        "physics": {"model": "graphics", "dimension": 3, "neighbour_search": "all_pairs", "equation_of_state": "tait",
                    "surface_tension": True, "precision": "float64"},
        "domain": {"box_min": [0.0, 0.0, 0.0], "box_max": [0.12, 0.1, 0.1]},
        "fluid": {"spacing": 0.01, "blocks": [{"min": [0.0, 0.0, 0.0], "max": [0.06, 0.06, 0.06]}],
                  "stiffness": 100.0, "viscosity": 1.0, "cohesion": 0.002},
        "time": {"dt": 1e-4},
    })


def jittered_state(scene, precision, seed):
    """(state, params, stages, spec): the scene's lattice moved by up to 0.3 spacing in float64 (so
    that positions are not float32 numbers), random velocities."""
    rng = np.random.default_rng(seed)
    x = scene.initial_positions().astype(np.float64)
    x += rng.uniform(-0.3, 0.3, x.shape) * scene["fluid.spacing"]
    params = scene.params(len(x))
    state = empty_state(params, precision)
    state["particle_x"][:, :scene.dim] = x
    state["particle_v"][:, :scene.dim] = rng.normal(0.0, 1.0, x.shape)
    return state, params, plan(scene), scene.spec


def test_particle_buffers_are_real_in_every_sph_shader():
    """A shader that declared a real-valued buffer as vec4/float would read the float64 build's
    buffers wrongly: every such declaration uses real (shaders/sph/real.glsl)."""
    real_buffers = {name for name, (dtype, _, _) in BUFFERS.items() if dtype == REAL}
    for shader in sorted((SHADER_DIR / "sph").glob("*.comp")):
        text = shader.read_text()
        for kind, name in re.findall(r"buffer\s+\w+\s*\{\s*(\w+)\s+(\w+)\[\];", text):
            if name in real_buffers:
                assert kind in ("real", "real4"), f"{shader.name}: {name} is declared {kind}, not real"
        if re.search(r"\breal", text):
            assert '#include "real.glsl"' in text, f"{shader.name} uses real without including real.glsl"


# Per stage: both sides run the same float64 operations in the same order; on lavapipe the results
# are bitwise equal. A GPU may contract a * b + c into one fused multiply-add and round its double
# division and sqrt by its own rules (~1 ulp): over ~30 partly cancelling neighbour terms that stays
# below 1e-12 of each buffer's largest magnitude (float32's 1e-5 in test_backends, times the ratio
# of the two machine epsilons, 2^-29, is 2e-14; 1e-12 leaves room for the cancellation).
STAGE_RTOL = 1e-12
STEPS = 20
# 20 more steps: a difference of 1e-16 grows with the flow's sensitivity, as float32's does in
# test_backends (<= 1e-3 spacing after 100 steps from ~1e-7); 1e-9 spacing is the same margin.
STEP_ATOL_SPACINGS = 1e-9


@pytest.mark.parametrize("make_scene", [cube_drop_2d, corner_3d], ids=["2d", "3d"])
def test_float64_numba_and_vulkan_agree(open_backend, make_scene):
    scene = make_scene()
    state, params, stages, spec = jittered_state(scene, "float64", seed=5)
    cpu = open_backend("numba", params, state, stages, spec, precision="float64")
    gpu = open_backend("vulkan", params, state, stages, spec, precision="float64")
    for stage in stages:
        cpu.run_stage(stage)
        gpu.run_stage(stage)
        a, b = cpu.read(), gpu.read()
        for name in a:
            assert a[name].dtype == b[name].dtype == buffer_dtype(name, "float64"), name
        assert_stage_agrees(a, b, stage, STAGE_RTOL)
    cpu.step(STEPS)
    gpu.step(STEPS)
    x_cpu, x_gpu = particles(cpu, scene.dim)["particle_x"], particles(gpu, scene.dim)["particle_x"]
    assert np.abs(x_cpu - state["particle_x"][:, :scene.dim]).max() > 1e-2 * scene["fluid.spacing"], "nothing moved"
    gap = float(np.abs(x_cpu - x_gpu).max())
    assert gap <= STEP_ATOL_SPACINGS * scene["fluid.spacing"], f"positions differ by {gap:g} m after {STEPS + 1} steps"


def reference_density(x, params):
    """rho_i = density_coef sum_j (h2 - r2)^3 over all pairs within h, in float64 with numpy, from the
    same folded float32 constants the shaders read (the block is far from the walls: no images)."""
    h2, coef = float(params[0]["h2"]), float(params[0]["density_coef"])
    r2 = ((x[:, None, :] - x[None, :, :]) ** 2).sum(axis=-1)
    return coef * np.where(r2 < h2, (h2 - r2) ** 3, 0.0).sum(axis=1)


@pytest.mark.parametrize("backend", ["numba", "vulkan"])
def test_float64_density_matches_a_float64_reference(open_backend, backend):
    """The float64 build's density is the float64 sum: to 1e-12 relative (the sum of ~20 positive
    terms rounds to a few 1e-16), where the float32 build, from the same positions rounded to
    float32, is off by ~1e-6 (rounding of the positions and of h^2 - r^2)."""
    errors = {}
    for precision in ("float64", "float32"):
        scene = cube_drop_2d(precision)
        state, params, stages, spec = jittered_state(scene, precision, seed=7)
        x = jittered_state(scene, "float64", seed=7)[0]["particle_x"][:, :2]
        lo, hi = np.array(scene["domain.box_min"]), np.array(scene["domain.box_max"])
        assert ((x - lo).min() > scene.h) and ((hi - x).min() > scene.h), "the reference has no wall images"
        be = open_backend(backend, params, state, stages, spec, precision=precision)
        for stage in stages[:stages.index(Stage("compute_density")) + 1]:
            be.run_stage(stage)
        rho = particles(be, 2)["particle_rho"]
        assert rho.dtype == np.dtype(precision)
        ref = reference_density(x, params)
        errors[precision] = float((np.abs(rho - ref) / ref).max())
    assert errors["float64"] <= 1e-12, errors
    assert 1e-8 <= errors["float32"] <= 1e-4, errors  # the test tells the two builds apart


@pytest.mark.parametrize("backend", ["numba", "vulkan"])
def test_float64_run_writes_float64(tmp_path, backend):
    """final.npz and the snapshots keep the state's float64."""
    if backend == "vulkan":
        vulkan_or_skip()
    arrays = run(cube_drop_2d(), backend=backend, steps=4, out_dir=tmp_path, progress=False)
    with np.load(tmp_path / "final.npz") as final:
        for key in ("position", "velocity", "density", "pressure"):
            assert final[key].dtype == np.float64, key
            assert np.array_equal(final[key], arrays[key])
        assert np.abs(final["position"] - cube_drop_2d().initial_positions()).max() > 0, "nothing moved"
    snapshots = sorted(tmp_path.glob("cube_drop_2d_*.vtp"))
    assert snapshots
    types = {a.get("Name"): a.get("type") for a in ET.parse(snapshots[-1]).iter("DataArray")}
    assert {types[k] for k in ("velocity", "density", "pressure")} == {"Float64"}, types


def test_float64_on_a_device_without_shader_float64(tmp_path, capsys, monkeypatch):
    """One line that names the feature and both ways out; a float32 scene still runs there."""
    vulkan_or_skip()
    from sphcore.vk_runner import Context
    monkeypatch.setattr(Context, "_supports_float64", lambda self: False)
    path = tmp_path / "scene.toml"
    text = scene_path("cube_drop_2d").read_text()
    assert '\nmodel = "graphics"' in text  # (its [physics] table)
    path.write_text(text.replace('\nmodel = "graphics"', '\nmodel = "graphics"\nprecision = "float64"'))
    code = main(["run", str(path), "--backend", "vulkan", "--steps", "1", "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 1, err
    assert "Traceback" not in err
    message = err.split("sphcore: error: ", 1)[1]
    assert message.count("\n") == 1, message
    assert "shaderFloat64" in message and 'physics.precision = "float32"' in message and "--backend numba" in message
    assert not (tmp_path / "out" / "final.npz").exists()
    with Context() as ctx:  # the feature is only required of a float64 build
        assert not ctx.shader_float64
