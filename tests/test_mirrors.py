"""Every shader has its numba mirror; the numbered step labels appear in the same order."""
import re
from pathlib import Path

import pytest

from sphcore.params import DISPATCH_DTYPE, PARAMS_DTYPE, SHADER_DIR, dtype_from_glsl_block

ROOT = Path(__file__).resolve().parent.parent
SHADERS = sorted(SHADER_DIR.rglob("*.comp"))


def mirror_of(shader):
    return ROOT / "sphcore" / shader.relative_to(SHADER_DIR).with_suffix(".py")


def labels(text, comment):
    return re.findall(rf"{re.escape(comment)}\s*\[(\d+[a-z]?)\]", text)


def test_shaders_exist():
    assert SHADERS, f"no shaders under {SHADER_DIR}"


@pytest.mark.parametrize("shader", SHADERS, ids=lambda p: p.stem)
def test_every_shader_has_a_mirror(shader):
    assert mirror_of(shader).is_file(), f"{shader} has no numba mirror at {mirror_of(shader)}"


@pytest.mark.parametrize("shader", SHADERS, ids=lambda p: p.stem)
def test_step_labels_match_in_order(shader):
    glsl = labels(shader.read_text(), "//")
    python = labels(mirror_of(shader).read_text(), "#")
    assert glsl, f"{shader.name} has no numbered step labels"
    assert glsl == python, f"{shader.name} labels {glsl} != mirror labels {python}"
    assert glsl == [str(i) for i in range(1, len(glsl) + 1)], f"{shader.name}: labels not numbered 1..n: {glsl}"


@pytest.mark.parametrize("shader", SHADERS, ids=lambda p: p.stem)
def test_each_file_names_its_partner(shader):
    assert f"sphcore/{mirror_of(shader).relative_to(ROOT / 'sphcore')}" in shader.read_text()
    assert f"shaders/{shader.relative_to(SHADER_DIR)}" in mirror_of(shader).read_text()


def test_every_mirror_has_a_shader():
    not_mirrors = {"__init__.py", "generate_tables.py"}  # tables.py mirrors the generated tables.glsl
    mirrors = [p for d in ("sph", "mc") for p in (ROOT / "sphcore" / d).glob("*.py") if p.name not in not_mirrors]
    for mirror in mirrors:
        partners = [SHADER_DIR / mirror.parent.name / f"{mirror.stem}{suffix}" for suffix in (".comp", ".glsl")]
        assert any(p.is_file() for p in partners), f"{mirror} mirrors no shader"


def test_included_helpers_have_mirrors_with_the_same_functions():
    for include in SHADER_DIR.rglob("*.glsl"):
        functions = re.findall(r"^\w+\s+(\w+)\s*\([^;]*\)\s*\{", include.read_text(), re.M)
        if not functions:
            continue  # a block of declarations (params.glsl, constants.glsl), parsed by sphcore.params
        mirror = mirror_of(include)
        assert mirror.is_file(), f"{include} has no mirror at {mirror}"
        text = mirror.read_text()
        assert f"shaders/{include.relative_to(SHADER_DIR)}" in text
        for name in functions:
            assert f"def {name}(" in text, f"{include.name}: function {name} has no mirror in {mirror.name}"


def test_specialization_constants_are_parsed_from_the_shaders():
    from sphcore.params import MC_SPEC_CONSTANTS, SPEC_CONSTANTS, Spec
    assert list(Spec._fields) == list(SPEC_CONSTANTS)
    # (the surface's shaders take both sets: sphcore/surface.py)
    ids = [cid for cid, _ in SPEC_CONSTANTS.values()] + [cid for cid, _ in MC_SPEC_CONSTANTS.values()]
    assert len(set(ids)) == len(ids) and 0 not in ids, "constant 0 is the work-group size"
    assert {"DIM", "GRID", "WALLS", "TAIT", "VISCOSITY", "SURFACE_TENSION", "GRAVITY"} <= set(SPEC_CONSTANTS)


def test_parameter_layout_follows_std430():
    text = "uniform B { uint n; float a; vec2 g; float b; vec3 c; float d; } P;"
    dtype = dtype_from_glsl_block(text)
    assert [dtype.fields[k][1] for k in ("n", "a", "g", "b", "c", "d")] == [0, 4, 8, 16, 32, 44]
    assert PARAMS_DTYPE.itemsize <= 16384, "a uniform buffer beyond the 16 KiB every device supports"
    assert DISPATCH_DTYPE.itemsize <= 128, "push constants beyond the 128 bytes every device supports"
