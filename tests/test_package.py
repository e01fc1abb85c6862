"""Installing and using sphcore as a user would: the README's commands are what CI runs, the wheel
installs nothing but the sphcore package and runs from any folder on both backends, and the README's
Python example (examples/quickstart.py) runs."""
import os
import re
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

import numpy as np
import pytest

from conftest import vulkan_or_skip

ROOT = Path(__file__).resolve().parent.parent
EXAMPLE = ROOT / "examples" / "quickstart.py"


def readme_block(heading, language):
    """The first ```language block after the README line `heading`."""
    text = (ROOT / "README.md").read_text()
    after = text[text.index(heading + "\n"):]
    return re.search(rf"```{language}\n(.*?)```", after, re.S).group(1)


def test_ci_runs_the_readme_commands_verbatim():
    commands = [line for line in readme_block("## Two commands", "sh").splitlines() if line and not line.startswith("#")]
    assert len(commands) == 2 and all(c.startswith("./setup.sh && ") for c in commands)
    ci = (ROOT / ".ci" / "run").read_text().splitlines()
    for command in commands:
        assert command in ci, f".ci/run does not run the README's {command!r}"
    assert "export PATH=/usr/bin:/bin" in ci  # the distribution's python3 alone, as on a fresh machine


def test_readme_python_example_is_the_example_script():
    code = EXAMPLE.read_text()
    code = code[code.index('"""', 3) + 4:]  # after the module docstring
    assert readme_block("## Python API", "python").strip() == code.strip()


def test_example_script_runs_from_another_folder(tmp_path):
    """examples/quickstart.py as a user runs it: four snapshots, a front that moves, a surface and its picture."""
    proc = subprocess.run([sys.executable, str(EXAMPLE)], cwd=tmp_path, capture_output=True, text=True,
                          env={**os.environ, "OMP_WAIT_POLICY": "passive"}, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    fronts = [float(x) for x in re.findall(r"front at x = ([\d.]+) m", proc.stdout)]
    assert len(fronts) == 4 and fronts[-1] > fronts[0], proc.stdout  # the column collapses
    assert int(re.search(r"surface: (\d+) vertices", proc.stdout).group(1)) > 100
    out = tmp_path / "quickstart"
    assert len(list(out.glob("quickstart_*.vtp"))) == 4 and (out / "quickstart.pvd").is_file()
    assert (out / "surface.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def wheel(tmp_path_factory):
    out = tmp_path_factory.mktemp("wheel")
    proc = subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "-w", str(out), str(ROOT)],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    (path,) = out.glob("sphcore-*.whl")
    return path


def test_wheel_holds_only_the_sphcore_package(wheel):
    names = zipfile.ZipFile(wheel).namelist()
    assert {n.split("/")[0] for n in names} == {"sphcore", f"{wheel.name.split('-py3')[0]}.dist-info"}
    for needed in ("sphcore/shaders/sph/compute_density.comp", "sphcore/shaders/pyramid.glsl",
                   "sphcore/scenes/dam_break_2d.toml", "sphcore/vk_runner/context.py",
                   "sphcore/data/martin_moyce_1952_table2_front_n2eq2_a2.25in_ocellaris.csv"):
        assert needed in names


def test_wheel_in_a_fresh_venv_runs_on_both_backends_from_another_folder(wheel, tmp_path):
    """The wheel in a new virtual environment (its dependencies seen through a .pth line to this
    environment's site-packages, so nothing is downloaded), run from a folder outside the checkout."""
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True)
    site = next((venv / "lib").glob("python3*/site-packages"))
    before = set(os.listdir(site))
    proc = subprocess.run([sys.executable, "-m", "pip", "--python", str(venv / "bin" / "python"), "install", "-q",
                           "--no-deps", "--no-index", str(wheel)], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    added = set(os.listdir(site)) - before
    assert {name for name in added if not name.endswith(".dist-info")} == {"sphcore"}, added
    (site / "dependencies.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    env = {**os.environ, "OMP_WAIT_POLICY": "passive"}
    where = subprocess.run([str(venv / "bin" / "python"), "-c", "import sphcore; print(sphcore.__file__)"],
                           cwd=elsewhere, capture_output=True, text=True, env=env)
    assert where.stdout.startswith(str(site)), where  # the installed copy, not the checkout's
    finals = {}
    for backend in ("numba", "vulkan"):
        if backend == "vulkan":
            vulkan_or_skip()
        proc = subprocess.run([str(venv / "bin" / "sphcore"), "run", "tank_2d", "--steps", "20", "--backend", backend,
                               "--out", backend], cwd=elsewhere, capture_output=True, text=True, env=env, timeout=600)
        assert proc.returncode == 0, proc.stderr[-3000:]
        with np.load(elsewhere / backend / "final.npz") as data:
            finals[backend] = data["position"]
    # the same shaders both ways (float32; sums in another order): positions within a micrometre
    np.testing.assert_allclose(finals["vulkan"], finals["numba"], atol=1e-6)
