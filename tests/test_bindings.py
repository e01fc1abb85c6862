"""The binding numbers the shaders declare by hand against backends.BUFFERS (binding = index) and the
buffers each stage binds (backends.STAGES): a buffer declared at the wrong number would read another
buffer's memory on Vulkan while its mirror reads the right one."""
import re

import numpy as np
import pytest

from sphcore.backends import BUFFERS, REAL, STAGES
from sphcore.paths import SHADER_DIR

DECLARATION = re.compile(r"layout\(std430, binding = (\d+)\)[^{]*\{\s*(\w+)\s+(\w+)\[\];\s*\};[ \t]*(// \(unread)?")
# GLSL element type -> (BUFFERS dtype, components per element in BUFFERS); a type with more components
# than its buffer is a view of it by chunks (neighbour_chunks: neighbours four words at a time), one with
# fewer a flat view (dt_partial's pairs, dfsph_history's rows as floats)
TYPES = {"real": (REAL, 1), "real4": (REAL, 4), "float": (np.float32, 1), "vec4": (np.float32, 4),
         "uint": (np.uint32, 1), "uvec2": (np.uint32, 2), "uvec4": (np.uint32, 4)}
NAMES = list(BUFFERS)


def declarations(stage):
    """[(binding, GLSL type, name, unread)] of shaders/sph/STAGE.comp and the includes it uses; unread: a
    declaration commented `// (unread...`, there only because an include's code names it (a specialization
    constant leaves it out), so the stage need not bind it."""
    source = (SHADER_DIR / "sph" / f"{stage}.comp").read_text()
    for include in re.findall(r'#include "(\w+\.glsl)"', source):
        path = SHADER_DIR / "sph" / include
        source += path.read_text() if path.exists() else ""
    return [(int(b), t, n, bool(u)) for b, t, n, u in DECLARATION.findall(source)]


@pytest.mark.parametrize("stage", sorted(STAGES))
def test_a_stage_declares_the_buffers_it_binds_at_their_numbers(stage):
    declared = declarations(stage)
    assert declared, f"{stage}.comp declares no buffer"
    bound = {NAMES.index(name) for name in STAGES[stage][2]}
    used = {b for b, _, _, unread in declared if not unread}
    assert used <= bound <= {b for b, _, _, _ in declared}, (
        f"{stage}.comp declares bindings {sorted(used)} (and unread ones), STAGES binds "
        f"{sorted(bound)} ({', '.join(STAGES[stage][2])})")
    for binding, glsl_type, name, _ in declared:
        dtype, components = BUFFERS[NAMES[binding]][:2]
        want_dtype, want_components = TYPES[glsl_type]
        assert dtype == want_dtype, f"{stage}.comp: {name} at binding {binding} is {glsl_type}, {NAMES[binding]} " \
                                    f"holds {dtype}"
        assert want_components % components == 0 or components % want_components == 0, \
            f"{stage}.comp: {name} at binding {binding} is {glsl_type}, {NAMES[binding]} has {components} components"


def test_a_buffer_declared_under_its_own_name_sits_at_its_number():
    """Where a shader names a buffer as BUFFERS does, the binding is that name's index (aliases such as
    particle_vstar for scratch_v are checked by type above)."""
    for stage in STAGES:
        for binding, _, name, _ in declarations(stage):
            if name in BUFFERS:
                assert binding == NAMES.index(name), f"{stage}.comp declares {name} at binding {binding}, " \
                                                     f"BUFFERS puts it at {NAMES.index(name)}"
