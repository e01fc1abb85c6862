import copy
import os

# numba's OpenMP workers spin between parallel loops; on a 2-core CI machine that starves
# lavapipe's threads. Must be set before numba starts its thread pool.
os.environ.setdefault("OMP_WAIT_POLICY", "passive")

import numpy as np
import pytest

from sphcore.backends import empty_state, in_particle_order, make_backend, plan
from sphcore.scene import Scene

BACKENDS = ["numba", "vulkan"]


def vulkan_or_skip():
    """Skip a Vulkan test where no Vulkan device exists, except in CI, where it must exist."""
    from sphcore.vk_runner import Context, VulkanError
    try:
        Context().close()
    except VulkanError as e:
        if os.environ.get("CI"):
            raise
        pytest.skip(f"no Vulkan here: {e}")


def skip_unless_compiler():
    """Skip a test that compiles shaders where no GLSL compiler exists, except in CI, where it must exist."""
    from sphcore.vk_runner import ShaderCompileError
    from sphcore.vk_runner.compiler import find_compiler
    try:
        find_compiler()
    except ShaderCompileError as e:
        if os.environ.get("CI"):
            raise
        pytest.skip(str(e))


# Vulkan validation layers on in the tests, unless SPHCORE_TEST_VALIDATION=0 (a GPU machine without them)
VALIDATION = os.environ.get("SPHCORE_TEST_VALIDATION", "1") != "0"


@pytest.fixture
def open_backend():
    """open_backend(name, params, state, stages, spec) -> backend with validation layers on (Vulkan).

    At teardown, asserts that the validation layers reported no error.
    """
    opened = []

    def open_(name, params, state, stages, spec, **options):
        if name == "vulkan":
            vulkan_or_skip()
            options.setdefault("validation", VALIDATION)
        backend = make_backend(name, params, state, stages, spec, **options)
        opened.append(backend)
        return backend

    yield open_
    for backend in opened:
        messages = list(backend.ctx.validation_messages) if backend.name == "vulkan" else []
        backend.close()
        assert messages == [], f"Vulkan validation errors: {messages}"


def scene_changed(base, **changes):
    """The Scene of dict `base` with each "table.key" of `changes` set to its value (`base` itself unchanged)."""
    data = copy.deepcopy(base)
    for dotted, value in changes.items():
        table, key = dotted.split(".")
        data.setdefault(table, {})[key] = value
    return Scene.from_dict(data)


def scene_state(scene, jitter=0.0, seed=0):
    """(state, params, stages, spec) of `scene`, positions jittered by up to `jitter` * spacing (seeded)."""
    x = scene.initial_positions()
    if jitter:
        rng = np.random.default_rng(seed)
        x = x + (rng.uniform(-1, 1, x.shape) * jitter * scene["fluid.spacing"]).astype(np.float32)
    params = scene.params(len(x))
    state = empty_state(params)
    state["particle_x"][:, :scene.dim] = x
    state["particle_rho"][:] = scene.initial_density(x)  # the state's density with physics.density = "continuity"
    return state, params, plan(scene), scene.spec


def particles(backend, dim):
    """A backend's per-particle arrays in particle-id order, vectors of `dim` components."""
    return in_particle_order(backend.read(), dim)


def schedule_dependent(stage):
    """Buffers whose contents depend on the order a GPU runs atomics in: the slots of count_cells,
    and the sorted order scatter_particles writes from them (sort_cells makes it exact again)."""
    return {"particle_slot", "sorted_index"} if stage.name == "scatter_particles" else {"particle_slot"}


def assert_stage_agrees(a, b, stage, rtol, least_scale=None):
    """Two backends' buffers after `stage`: integers bitwise, reals within rtol of each buffer's scale, at least
    least_scale[name] where given."""
    for name in a:
        if name in schedule_dependent(stage):
            continue
        if a[name].dtype.kind == "u":
            assert np.array_equal(a[name], b[name]), f"after {stage}: {name} differs"
            continue
        scale = max(float(np.abs(a[name]).max(initial=0.0)), (least_scale or {}).get(name, 0.0), 1e-300)
        err = float(np.abs(a[name] - b[name]).max(initial=0.0))
        assert err <= rtol * scale, f"after {stage}: {name} differs by {err:g} (scale {scale:g})"


def schema_keys(schema=None, prefix=""):
    """(dotted name, Key) of every scene key."""
    from sphcore.scene import SCHEMA

    for name, key in (SCHEMA if schema is None else schema).items():
        if isinstance(key, dict):
            yield from schema_keys(key, f"{prefix}{name}.")
        else:
            yield f"{prefix}{name}", key


def _validation_errors():
    """Every Vulkan validation-layer error reported in this process so far (any Context's)."""
    import sys
    context = sys.modules.get("sphcore.vk_runner.context")
    return [m for _, messages in context._INSTANCES.values() for m in messages] if context else []


@pytest.fixture(autouse=True)
def no_validation_errors():
    """A test fails on any Vulkan validation error reported while it ran, wherever it came from."""
    before = len(_validation_errors())
    yield
    new = _validation_errors()[before:]
    assert not new, f"Vulkan validation errors: {new}"
