"""The work-group emulation's rules (sphcore/workgroups.py, STYLE.md), on a shader written so that each of its
barriers changes the result if missing (tests/shaders/barrier_probe.comp). Its mirror below follows the rules:
one loop over the local invocations per phase between barriers, the group's shared memory an array of the
group, and a local that outlives a barrier an array by local id. It agrees bitwise with lavapipe. The same
body run one invocation after another (a mirror missing its barriers) does not, and neither does the shader
built without its barriers on lavapipe: the probe catches a missing barrier on either side.
"""
from pathlib import Path

import numpy as np
import pytest
from numba import njit, prange

from conftest import VALIDATION, vulkan_or_skip

PROBE = Path(__file__).parent / "shaders" / "barrier_probe.comp"
GROUPS = 5


@njit(parallel=True)
def barrier_probe(n_groups, local_size, x, y, sums):
    """Mirror of barrier_probe.comp: work groups in parallel, each phase a loop over the local ids."""
    for group in prange(n_groups):
        s = np.empty(local_size, np.float32)  # the group's shared memory
        mine = np.empty(local_size, np.float32)  # a local that outlives a barrier: one per invocation
        for lid in range(local_size):
            # [1] own value
            s[lid] = np.float32(2.0) * x[group * local_size + lid] + np.float32(lid)
        # (barrier)
        for lid in range(local_size):
            # [2] with the mirrored invocation's
            mine[lid] = np.float32(0.5) * s[lid] + s[local_size - 1 - lid]
            y[group * local_size + lid] = mine[lid]
        # (barrier)
        for lid in range(local_size):
            # [3] own slot overwritten, then the group's sum by halves
            s[lid] = mine[lid]
        # (barrier)
        stride = local_size // 2
        while stride > 0:
            for lid in range(stride):
                s[lid] += s[lid + stride]
            # (barrier)
            stride //= 2
        sums[group] = s[0]


@njit
def without_barriers(n_groups, local_size, x, y, sums):
    """The same body run from start to end by one invocation after another: a mirror that missed the barriers."""
    for group in range(n_groups):
        s = np.zeros(local_size, np.float32)
        for lid in range(local_size):
            s[lid] = np.float32(2.0) * x[group * local_size + lid] + np.float32(lid)
            mine = np.float32(0.5) * s[lid] + s[local_size - 1 - lid]
            y[group * local_size + lid] = mine
            s[lid] = mine
            stride = local_size // 2
            while stride > 0:
                if lid < stride:
                    s[lid] += s[lid + stride]
                stride //= 2
            if lid == 0:
                sums[group] = s[0]


def on_numba(mirror, x, local_size):
    y, sums = np.zeros_like(x), np.zeros(GROUPS, np.float32)
    mirror(GROUPS, local_size, x, y, sums)
    return y, sums


def on_vulkan(x, local_size, defines=()):
    from sphcore.vk_runner import Context, compile_glsl
    with Context(validation=VALIDATION) as ctx:
        buffers = [ctx.buffer(x.nbytes, "x"), ctx.buffer(x.nbytes, "y"), ctx.buffer(4 * GROUPS, "sums")]
        pipeline = ctx.pipeline(compile_glsl(PROBE, defines=defines), len(buffers), 4, local_size)
        try:
            buffers[0].write(x)
            pipeline.bind(buffers)
            rec = ctx.record()
            rec.dispatch(pipeline, np.zeros(1, np.uint32), groups=(GROUPS, 1, 1))
            rec.end()
            ctx.submit(rec)
            rec.free()
            out = buffers[1].read(np.float32, (len(x),)), buffers[2].read(np.float32, (GROUPS,)), ctx.device_type
        finally:
            pipeline.free()
            for b in buffers:
                b.free()
        assert list(ctx.validation_messages) == []
    return out


@pytest.mark.parametrize("local_size", [32, 128])
def test_the_mirror_of_a_shader_with_barriers_is_its_bits(local_size):
    vulkan_or_skip()
    x = np.random.default_rng(local_size).standard_normal(GROUPS * local_size).astype(np.float32)
    y, sums, device_type = on_vulkan(x, local_size)
    mirror_y, mirror_sums = on_numba(barrier_probe, x, local_size)
    assert np.array_equal(mirror_y, y) and np.array_equal(mirror_sums, sums)
    # what the probe computes, in float64: each group's sum of 0.5 s_l + s_(L-1-l), s_l = 2 x_l + l
    s = 2.0 * x.astype(np.float64).reshape(GROUPS, local_size) + np.arange(local_size)
    assert np.allclose(sums, (0.5 * s + s[:, ::-1]).sum(axis=1), rtol=1e-5)
    # a mirror without its barriers, and the shader without them, give other values
    y_missing, sums_missing = on_numba(without_barriers, x, local_size)
    assert not np.array_equal(y_missing, y) and not np.array_equal(sums_missing, sums)
    if device_type == "CPU":  # (lavapipe runs a group's invocations in chunks; a GPU's one warp may not show it)
        y_unsynced, sums_unsynced, _ = on_vulkan(x, local_size, defines=("NO_BARRIER",))
        assert not (np.array_equal(y_unsynced, y) and np.array_equal(sums_unsynced, sums))
