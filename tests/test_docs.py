"""The documentation site (docs/, issue 32): it builds with warnings as errors, its gallery's
examples run and leave their pictures, the scene-keys page says what `sphcore keys` says, and the
first scene of the getting-started page is a valid scene.

The build is the README's command on a copy of docs/ in a temporary folder: sphinx-gallery writes its
generated pages into the source folder (docs/auto_examples), where two builds at once (this module's tests split
over pytest-xdist's processes, each building the site) would write over each other's pages: a build failed once
so under `pytest -q`.
"""
import html.parser
import json
import re
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
EXAMPLES = sorted(p.stem for p in (ROOT / "examples").glob("plot_*.py"))


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """(html folder, build output) of `sphinx-build -W --keep-going -b html docs OUT`."""
    pytest.importorskip("sphinx")
    pytest.importorskip("sphinx_gallery")
    out = tmp_path_factory.mktemp("docs")
    tree = out / "tree"  # (docs/ copied; what its pages and conf.py name beside it, linked)
    shutil.copytree(DOCS, tree / "docs", ignore=shutil.ignore_patterns("_build", "auto_examples", "__pycache__"))
    for name in ("examples", "benchmarks", "validation"):
        (tree / name).symlink_to(ROOT / name)
    cmd = [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-b", "html", "-d", str(out / "doctrees"),
           str(tree / "docs"), str(out / "html")]
    done = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=900)
    return out / "html", done


def test_docs_build_without_warnings(site):
    html, done = site
    assert done.returncode == 0, f"sphinx-build failed:\n{done.stdout[-3000:]}\n{done.stderr[-6000:]}"
    for page in ("index", "getting_started", "scenes", "api", "auto_examples/index", "models/index",
                 "validation/index", "performance", "robustness", "contributing", "limitations"):
        assert (html / f"{page}.html").is_file(), f"{page}.html not built"
    api = (html / "api.html").read_text(encoding="utf-8")
    for name in ("Scene", "SceneError", "Simulation", "SimulationError", "run", "resume", "SnapshotSeries",
                 "marching_cubes", "particle_surface", "render_mesh"):
        assert f'id="sphcore.{name}"' in api, f"api.html does not document sphcore.{name}"


def test_gallery_examples_ran_and_drew(site):
    html, done = site
    assert done.returncode == 0, done.stderr[-3000:]
    assert len(EXAMPLES) >= 5, EXAMPLES
    for stem in EXAMPLES:
        assert (html / "auto_examples" / f"{stem}.html").is_file(), f"no gallery page for examples/{stem}.py"
        pictures = list((html / "_images").glob(f"sphx_glr_{stem}_*.png"))
        assert any(not p.name.endswith("_thumb.png") for p in pictures), f"examples/{stem}.py drew no picture"


class Tables(html.parser.HTMLParser):
    """The rows of the tables whose class has `cls`: lists of cell texts, whitespace collapsed."""

    def __init__(self, cls):
        super().__init__()
        self.cls, self.depth, self.rows, self.cell = cls, 0, [], None

    def handle_starttag(self, tag, attrs):
        if tag == "table":
            self.depth += 1 if (self.depth or self.cls in (dict(attrs).get("class") or "").split()) else 0
        elif self.depth and tag == "tr":
            self.rows.append([])
        elif self.depth and tag in ("td", "th"):
            self.cell = []

    def handle_endtag(self, tag):
        if tag == "table" and self.depth:
            self.depth -= 1
        elif self.depth and tag in ("td", "th") and self.cell is not None:
            self.rows[-1].append(" ".join("".join(self.cell).split()))
            self.cell = None

    def handle_data(self, data):
        if self.cell is not None:
            self.cell.append(data)


def cli_keys():
    """{key: (default, unit, range)} as `sphcore keys` prints them."""
    done = subprocess.run([sys.executable, "-m", "sphcore", "keys"], capture_output=True, text=True, timeout=120,
                          cwd=ROOT)
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert lines[0].split()[:2] == ["key", "default"], lines[0]
    keys = {}
    for line in lines[1:]:
        key = line.split()[0]
        rest = line[len(key):].lstrip()
        default, end = json.JSONDecoder().raw_decode(rest)
        tail = rest[end:]
        if not tail[:27].strip():  # no unit, no range (a string or a switch)
            unit = span = ""
        else:
            m = re.match(r"\s*(?P<unit>.*?)\s+(?P<span>\[[^\]]*\]|\S+\|\S+)\s", tail)
            assert m, f"cannot read unit and range of: {line}"
            unit, span = m["unit"], m["span"]
        keys[key] = (json.dumps(default), unit, span)
    return keys


def test_scene_keys_page_matches_sphcore_keys(site):
    html, done = site
    assert done.returncode == 0, done.stderr[-3000:]
    parser = Tables("scene-keys")
    parser.feed((html / "scenes.html").read_text(encoding="utf-8"))
    header = parser.rows[0]
    assert header[:5] == ["key", "default", "unit", "range", "type"], header
    page = {}
    for row in parser.rows:
        if row != header:
            page[row[0]] = row
    expected = cli_keys()
    assert len(expected) > 30
    assert sorted(page) == sorted(expected), set(page) ^ set(expected)
    for key, (default, unit, span) in expected.items():
        row = page[key]
        assert json.loads(row[1]) == json.loads(default), (key, row[1], default)
        assert row[2] == unit, (key, row[2], unit)
        assert row[3].replace(" ", "") == span.replace(" ", ""), (key, row[3], span)
        assert row[5], f"{key}: no meaning on the page"


def test_getting_started_scene_loads_as_described():
    from sphcore.scene import Scene

    text = (DOCS / "getting_started.md").read_text(encoding="utf-8")
    blocks = re.findall(r"```toml\n(.*?)```", text, re.S)
    first = [b for b in blocks if "my_first_scene" in b]
    assert len(first) == 1
    scene = Scene.from_dict(tomllib.loads(first[0]), "getting_started.md")
    assert len(scene.initial_positions()) == 600  # "20 x 30 = 600 particles at 1 cm", as the page says
    assert scene["domain.obstacles"] and scene["time.dt"] == "adaptive"


def test_api_docstring_examples_run(tmp_path, monkeypatch):
    """Every public name of sphcore (sphcore._PUBLIC, the API page) has a runnable example in its
    docstring or its methods', and the examples print what they say."""
    import doctest
    import inspect

    import sphcore

    monkeypatch.chdir(tmp_path)  # anything an example writes outside its temporary folder lands here
    finder = doctest.DocTestFinder()
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    missing = []
    for name in sphcore._PUBLIC:
        obj = getattr(sphcore, name)
        tests = [t for t in finder.find(obj, f"sphcore.{name}", module=inspect.getmodule(obj), globs={})
                 if t.examples]
        if not tests:
            missing.append(name)
        for test in tests:
            runner.run(test)
    assert not missing, f"no example in the docstrings of: {', '.join(missing)}"
    result = runner.summarize(verbose=False)
    assert result.attempted > 20 and result.failed == 0, result
