"""Every shader has its numba mirror; the numbered step labels appear in the same order."""
import re
from pathlib import Path

import pytest

from sphcore.params import PARAMS_DTYPE, SHADER_DIR, dtype_from_glsl_block

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
    mirrors = [p for p in (ROOT / "sphcore" / "sph").glob("*.py") if p.name != "__init__.py"]
    for mirror in mirrors:
        assert (SHADER_DIR / "sph" / f"{mirror.stem}.comp").is_file(), f"{mirror} mirrors no shader"


def test_parameter_layout_follows_std430():
    text = "uniform B { uint n; float a; vec2 g; float b; vec3 c; float d; } P;"
    dtype = dtype_from_glsl_block(text)
    assert [dtype.fields[k][1] for k in ("n", "a", "g", "b", "c", "d")] == [0, 4, 8, 16, 32, 44]
    assert PARAMS_DTYPE.itemsize <= 128, "push constants beyond the 128 bytes every device supports"
