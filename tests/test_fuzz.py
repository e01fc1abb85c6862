"""The scene parser and the command line, fuzzed with hypothesis: every input either runs or is
rejected with a message that names the key (and its range); nothing else escapes.

Derandomized, so CI tries the same inputs every time; each test prints how many it tried.
Runs stay tiny: a scene is parsed and its parameter block folded; the command line runs at
most a few steps of a 36-particle scene (numba, compiled once for the module).
"""
import contextlib
import copy
import io
import json
import math
import os
import re
from datetime import date, datetime
from functools import reduce

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from conftest import schema_keys
from hypothesis import strategies as st

from sphcore.cli import main
from sphcore.scene import MAX_PARTICLES, SCHEMA, Key, Scene, SceneError

FUZZ = settings(deadline=None, derandomize=True, database=None, suppress_health_check=list(HealthCheck))

BASE = {
    "name": "tiny",
    "physics": {"model": "graphics"},
    "fluid": {"spacing": 0.05, "blocks": [{"min": [0.3, 0.4], "max": [0.6, 0.7]}]},
    "time": {"dt": 1e-3, "steps": 3, "output_every": 2, "checkpoint_every": 2},
}


KEYS = dict(schema_keys())
TABLES = [name for name, key in SCHEMA.items() if isinstance(key, dict)]
DOTTED = re.compile(r"\b(" + "|".join(re.escape(k) for k in sorted(KEYS, key=len, reverse=True)) + r")\b")

# ---- values ----

finite = st.floats(allow_nan=False, allow_infinity=False)
numbers = st.one_of(
    st.integers(-10, 10), st.integers(), st.sampled_from([10**400, -10**400, 10**40, 2**63, -2**63, 2**31]),
    st.floats(), st.sampled_from([math.nan, math.inf, -math.inf, 1e308, -1e308, 5e-324, -0.0, 1e-9, 1e9]),
)
vectors = st.lists(st.one_of(numbers, st.booleans()), max_size=4)
blocks = st.lists(st.dictionaries(st.sampled_from(["min", "max", "mid"]), vectors, max_size=3), max_size=3)
wild = st.one_of(
    numbers, st.booleans(), st.none(), st.text(max_size=12),
    st.sampled_from(["auto", "grid", "all_pairs", "tait", "linear", "open", "walls", "float64", "", "../x", "a/b"]),
    st.datetimes(), st.dates(), vectors, blocks, st.dictionaries(st.text(max_size=4), numbers, max_size=3),
)


def near(key: Key):
    """Values at and around a key's range, and of its own kind."""
    if key.kind in ("float", "dt", "int"):
        lo, hi = key.low, key.high
        edges = [lo, hi, lo - abs(lo) * 0.01 - 1e-12, hi * 1.01 + 1e-12, lo / 2, hi * 2]
        inside = st.floats(min_value=lo, max_value=hi) if key.kind != "int" else st.integers(int(lo), int(hi))
        return st.one_of(st.sampled_from([int(v) if key.kind == "int" else v for v in edges]), inside)
    if key.kind == "vec":
        return st.lists(st.floats(min_value=key.low * 1.1, max_value=key.high * 1.1), min_size=1, max_size=4)
    if key.kind == "blocks":
        corner = st.lists(st.floats(-2.0, 2.0), min_size=2, max_size=3)
        return st.lists(st.fixed_dictionaries({"min": corner, "max": corner}), min_size=1, max_size=2)
    if "|" in key.kind:
        return st.sampled_from(key.kind.split("|") + ["other"])
    if key.kind == "bool":
        return st.booleans()
    return st.text(max_size=12)


def set_key(scene, dotted, value):
    """A copy of scene dict `scene` with `dotted` ("table.key", "key" or "table") set to `value`."""
    scene = copy.deepcopy(scene)
    *tables, leaf = dotted.split(".")
    node = scene
    for table in tables:
        if not isinstance(node.get(table), dict):
            node[table] = {}
        node = node[table]
    node[leaf] = value
    return scene


changes = st.one_of(
    st.tuples(st.sampled_from(sorted(KEYS)), wild),
    st.sampled_from(sorted(KEYS)).flatmap(lambda k: st.tuples(st.just(k), near(KEYS[k]))),
    st.tuples(st.sampled_from(TABLES + ["name"]), wild),
    st.tuples(st.sampled_from(TABLES).map(lambda t: f"{t}.stifness"), wild),  # a typo: an unknown key
    st.tuples(st.sampled_from(["extra", "Fluid"]), wild),
)

# ---- what an accepted scene must satisfy ----


def check_accepted(scene):
    """A scene that parsed runs: positions inside the box, a positive finite dt, a finite
    parameter block, at most MAX_PARTICLES particles."""
    x = scene.initial_positions()
    assert 0 < len(x) <= MAX_PARTICLES and np.isfinite(x).all()
    lo, hi = np.float32(scene["domain.box_min"]), np.float32(scene["domain.box_max"])  # the walls as run
    assert ((x >= lo) & (x <= hi)).all()
    assert 0 < scene.dt < math.inf
    params = scene.params(len(x))
    for field in params.dtype.names:
        assert np.isfinite(params[0][field]).all(), (field, params[0][field])
    json.loads(scene.to_json())


def names_a_key(message, changed):
    """The message names the changed key: as a dotted path, or for an unknown key its table and name."""
    table, _, leaf = changed.rpartition(".")
    if changed in KEYS or changed in TABLES:
        return changed in message
    return repr(leaf) in message and (table in message if table else True)


tried = {}


@pytest.fixture(scope="module", autouse=True)
def report_counts():
    yield
    print("\nfuzzed inputs tried: " + ", ".join(f"{name} {count}" for name, count in tried.items()))


def count(name):
    tried[name] = tried.get(name, 0) + 1


@settings(FUZZ, max_examples=1500)
@given(change=changes)
def test_one_changed_key_runs_or_is_named(change):
    count("one key")
    dotted, value = change
    data = set_key(BASE, dotted, value)
    try:
        scene = Scene.from_dict(data)
    except SceneError as e:
        message = str(e)
        assert names_a_key(message, dotted), (dotted, value, message)
        if dotted in KEYS and "must be within" in message:
            key = KEYS[dotted]
            assert f"[{key.low:g}, {key.high:g}]" in message  # the allowed range
        return
    check_accepted(scene)


@settings(FUZZ, max_examples=700)
@given(change=st.lists(changes, min_size=2, max_size=5))
def test_many_changed_keys_run_or_are_named(change):
    count("several keys")
    data = BASE
    for dotted, value in change:
        data = set_key(data, dotted, value)
    try:
        scene = Scene.from_dict(data)
    except SceneError as e:
        assert DOTTED.search(str(e)) or any(names_a_key(str(e), d) for d, _ in change), (change, str(e))
        return
    check_accepted(scene)


@st.composite
def whole_scenes(draw):
    """Scenes valid key by key, at every scale the ranges allow: spacing from 10 um to 1 m, the
    box a few h wide or many, every switch, every coefficient anywhere in its range."""
    dim = draw(st.sampled_from([2, 3]))
    dx = draw(st.floats(1e-5, 1.0))
    ratio = draw(st.floats(1.5, 6.0))
    h = dx * ratio
    size = [h * draw(st.floats(2.001, 40.0)) for _ in range(dim)]
    lo = [draw(st.floats(-1e3, 1e3 - s)) for s in size] if max(size) < 2e3 else [-1e3] * dim
    hi = [a + s for a, s in zip(lo, size)]
    fill = [min(hi[a], lo[a] + max(dx * 1.5, size[a] * draw(st.floats(0.0, 1.0)))) for a in range(dim)]
    fluid = {"spacing": dx, "smoothing_ratio": ratio, "blocks": [{"min": lo, "max": fill}]}
    for name in ("rest_density", "stiffness", "viscosity", "cohesion"):
        key = KEYS[f"fluid.{name}"]
        fluid[name] = draw(st.one_of(st.sampled_from([key.low, key.high]), st.floats(key.low, key.high)))
    physics = {"model": "graphics", "dimension": dim}
    for name in ("neighbour_search", "equation_of_state", "viscosity", "surface_tension", "gravity"):
        physics[name] = draw(st.sampled_from(KEYS[f"physics.{name}"].kind.split("|"))
                             if "|" in KEYS[f"physics.{name}"].kind else st.booleans())
    return {
        "name": "fuzz", "physics": physics, "fluid": fluid,
        "domain": {"box_min": lo, "box_max": hi, "boundary": draw(st.sampled_from(["walls", "open"]))},
        "forces": {"gravity": [draw(st.floats(-1e4, 1e4)) for _ in range(dim)]},
        "walls": {"restitution": draw(st.floats(0.0, 1.0))},
        "time": {"dt": draw(st.one_of(st.just("auto"), st.floats(1e-8, 1.0))), "dt_fraction": draw(st.floats(0.01, 10.0))},
    }


@settings(FUZZ, max_examples=700)
@given(data=whole_scenes())
def test_whole_scenes_run_or_are_named(data):
    count("whole scenes")
    try:
        scene = Scene.from_dict(data)
    except SceneError as e:
        assert DOTTED.search(str(e)), str(e)
        count("whole scenes rejected")
        return
    check_accepted(scene)


@settings(FUZZ, max_examples=100)
@given(data=st.one_of(wild, st.lists(wild, max_size=3)).filter(lambda d: not isinstance(d, dict)))
def test_not_a_table_at_all(data):
    count("not a table")
    with pytest.raises(SceneError, match="expected a table"):
        Scene.from_dict(data)


# ---- scene files: TOML text, encodings, junk ----

def toml_value(v):
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf") if math.isinf(v) else repr(v)
    if isinstance(v, (int, datetime, date)):
        return v.isoformat() if not isinstance(v, int) else str(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, list):
        return "[" + ", ".join(toml_value(x) for x in v if x is not None) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{json.dumps(k)} = {toml_value(x)}" for k, x in v.items() if x is not None) + "}"
    return '"none"'


def toml_text(data):
    lines = [f"{json.dumps(k)} = {toml_value(v)}" for k, v in data.items() if not isinstance(v, dict)]
    for table, body in data.items():
        if isinstance(body, dict):
            lines.append(f"[{json.dumps(table)}]")
            lines += [f"{json.dumps(k)} = {toml_value(v)}" for k, v in body.items() if v is not None]
    return "\n".join(lines) + "\n"


scene_texts = st.lists(changes, max_size=3).map(lambda cs: toml_text(reduce(lambda d, c: set_key(d, *c), cs, BASE)))
scene_bytes = st.one_of(
    scene_texts.map(lambda t: t.encode("utf-8", "surrogatepass")),
    scene_texts.map(lambda t: t.encode("utf-8-sig", "surrogatepass")),  # with a byte-order mark
    scene_texts.map(lambda t: t.encode("utf-16")),
    scene_texts.map(lambda t: t.encode("latin-1", "replace")),
    st.tuples(scene_texts, st.integers(0, 400)).map(lambda p: p[0].encode("utf-8", "surrogatepass")[:p[1]]),
    st.binary(max_size=200),
    st.sampled_from([b"", b"\x00" * 10, b"\xff\xfe\x00", b"[", b"a = " + b"[" * 5000 + b"]" * 5000,
                     b"[[fluid]]\n", b'name = "x"\nname = "y"\n', b"[fluid.blocks]\nmin = 1\n"]),
)


@settings(FUZZ, max_examples=800)
@given(content=scene_bytes)
def test_scene_files_run_or_are_named(tmp_path_factory, content):
    count("scene files")
    path = tmp_path_factory.getbasetemp() / "fuzz_scene.toml"
    path.write_bytes(content)
    try:
        scene = Scene.load(path)
    except SceneError as e:
        assert str(e).startswith(f"{path}: "), str(e)
        return
    check_accepted(scene)


def test_a_folder_or_unreadable_file_as_scene(tmp_path):
    with pytest.raises(SceneError, match=re.escape(f"{tmp_path}: cannot read")):
        Scene.load(tmp_path)


# ---- the command line ----

@pytest.fixture(scope="module")
def cli_world(tmp_path_factory):
    """A tiny scene file, a finished run of it, and junk, as paths for random argv."""
    root = tmp_path_factory.mktemp("cli")
    scene = root / "tiny.toml"
    scene.write_text(toml_text(BASE))
    assert main(["run", str(scene), "--out", str(root / "done"), "--steps", "2"]) == 0
    (root / "junk.toml").write_bytes(b"\xff\xfe junk \x00")
    return root


@st.composite
def command_lines(draw, root):
    """`sphcore` command lines: a subcommand, its options in any order with good and bad values,
    and now and then a stray token. No value is a large integer: `run --steps N` stays short."""
    junk = st.text(st.characters(blacklist_categories=("Cs",), blacklist_characters="\x00"), max_size=10).filter(
        lambda t: not (t.strip().lstrip("+-").isdigit() and abs(int(t)) > 6))
    paths = st.sampled_from([str(root / "tiny.toml"), str(root / "done"), str(root / "junk.toml"), str(root),
                             str(root / "missing"), str(root / "tiny.toml" / "sub"), "tiny", "cube_drop_2d"])
    numbers = st.sampled_from(["0", "1", "2", "-1", "2.5", "nan", "inf", "-inf", "1e-9", "0x10", "", "x"])
    values = {
        "--steps": numbers, "--out": paths, "--resume": paths, "--backend": st.sampled_from(["numba", "cuda", ""]),
        "--local-size": st.sampled_from(["0", "1", "64", "1024", "2000", "-5", "x"]), "--device": junk,
        "--spacing": numbers, "--level": numbers, "--every": numbers, "--format": st.sampled_from(["vtp", "ply", "obj"]),
    }
    flags = {"run": ["--steps", "--out", "--resume", "--backend", "--local-size", "--device", "--validation"],
             "plot": ["--out"], "keys": [],
             "render": ["--out", "--backend", "--spacing", "--level", "--every", "--format", "--particles"]}
    command = draw(st.sampled_from(["run", "run", "run", "plot", "keys", "render", "-h", "frobnicate"]))
    argv = [command]
    if command in ("run", "plot", "render") and draw(st.integers(0, 3)):
        argv.append(draw(paths))
    for flag in draw(st.lists(st.sampled_from(flags.get(command) or ["--steps"]), max_size=4, unique=True)):
        argv += [flag] if flag in ("--validation", "--particles") else [flag, draw(values[flag])]
    for _ in range(draw(st.integers(0, 1))):  # a stray token somewhere
        argv.insert(draw(st.integers(0, len(argv))), draw(st.one_of(junk, paths, numbers)))
    return argv


@settings(FUZZ, max_examples=250)
@given(data=st.data())
def test_random_command_lines(cli_world, data):
    count("command lines")
    argv = data.draw(command_lines(cli_world))
    if argv[:1] == ["run"] and "--steps" not in argv:
        argv += ["--steps", "2"]  # never a scene's full 5000 steps
    if "--out" not in argv and "--resume" not in argv:
        argv += ["--out", str(cli_world / "out")]  # never runs/ in the working folder
    stdout, stderr = io.StringIO(), io.StringIO()
    here = os.getcwd()
    os.chdir(cli_world)  # a relative --out ("cube_drop_2d") lands in the test's folder, not the checkout
    with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
        try:
            code = main(argv)
        except SystemExit as e:  # argparse: usage errors (2) and --help (0)
            code = e.code
        finally:
            os.chdir(here)
    err = stderr.getvalue()
    assert "Traceback" not in err
    assert code in (0, 1, 2), (argv, code, err)
    count(f"command lines exiting {code}")
    if code == 1:
        assert err.strip().splitlines()[-1].split("\r")[-1].startswith("sphcore: error: "), (argv, err)
    if code == 2:
        assert "usage: sphcore" in err, (argv, err)
