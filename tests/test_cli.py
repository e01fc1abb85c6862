"""The command line end to end: `sphcore run`, `sphcore keys`, `sphcore plot`."""
import json
import re
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from conftest import schema_keys, vulkan_or_skip
from sphcore.cli import main
from sphcore.scene import Scene

STEPS = 20
EVERY = 8  # snapshots at 0, 8, 16 and at the end, 20

# 6 x 6 = 36 particles dropping from rest. dt = 1e-3 s is within the CFL bound
# 0.25 h / c = 0.25 * 0.1 m / 20 m/s = 1.25e-3 s, and large enough that 20 steps move
# the particles by millimetres, so comparing backends to 1e-4 m is not vacuous.
TINY = f"""\
name = "tiny"
[physics]
model = "graphics"
[fluid]
spacing = 0.05
blocks = [{{ min = [0.3, 0.4], max = [0.6, 0.7] }}]
[time]
dt = 1e-3
steps = 5000
output_every = {EVERY}
"""


def run_cli(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    assert code == 0, err
    return out


def snapshot_steps(out_dir, name):
    """Steps and times listed in OUT_DIR/NAME.pvd, checking that every file exists."""
    root = ET.parse(out_dir / f"{name}.pvd").getroot()
    assert root.get("type") == "Collection"
    steps, times = [], []
    for ds in root.iter("DataSet"):
        m = re.fullmatch(rf"{name}_(\d{{7}})\.vtp", ds.get("file"))
        assert m, ds.get("file")
        assert (out_dir / ds.get("file")).is_file()
        steps.append(int(m.group(1)))
        times.append(float(ds.get("timestep")))
    return steps, times


def check_run(out_dir, scene, steps):
    """final.npz and the snapshot series of a finished run of `scene`; returns final.npz's arrays."""
    data = dict(np.load(out_dir / "final.npz"))
    n = len(scene.initial_positions())
    for key in ("position", "velocity"):
        assert data[key].shape == (n, 2) and data[key].dtype == np.float32, key
    for key in ("density", "pressure"):
        assert data[key].shape == (n,) and data[key].dtype == np.float32, key
    for key in ("position", "velocity", "density", "pressure"):
        assert np.isfinite(data[key]).all(), key
    assert int(data["step"]) == steps
    assert float(data["time"]) == pytest.approx(steps * scene["time.dt"], rel=1e-6)
    assert json.loads(str(data["scene"])) == scene.config
    lo, hi = np.array(scene["domain.box_min"]), np.array(scene["domain.box_max"])
    assert ((data["position"] >= lo) & (data["position"] <= hi)).all()
    assert (data["density"] > 0).all() and (data["pressure"] >= 0).all()

    every = scene["time.output_every"]
    listed, times = snapshot_steps(out_dir, scene["name"])
    assert listed == sorted(set(range(0, steps, every)) | {steps})
    assert times == pytest.approx([s * scene["time.dt"] for s in listed], rel=1e-6)
    vtps = sorted(p.name for p in out_dir.glob("*.vtp"))
    assert vtps == [f"{scene['name']}_{s:07d}.vtp" for s in listed]
    for name in vtps:
        piece = ET.parse(out_dir / name).getroot().find("PolyData/Piece")
        assert piece.get("NumberOfPoints") == str(n)
    assert not list(out_dir.glob(".*tmp*"))  # no temporary files left behind
    return data


@pytest.fixture(scope="module")
def tiny_scene_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("scene") / "tiny.toml"
    path.write_text(TINY)
    return path


@pytest.fixture(scope="module")
def numba_run(tiny_scene_file, tmp_path_factory):
    """`sphcore run tiny.toml --steps 20 --out DIR`, run once for this module; returns DIR."""
    out_dir = tmp_path_factory.mktemp("numba_run")
    assert main(["run", str(tiny_scene_file), "--steps", str(STEPS), "--out", str(out_dir)]) == 0
    return out_dir


def test_run_numba(numba_run, tiny_scene_file):
    scene = Scene.load(tiny_scene_file)
    data = check_run(numba_run, scene, STEPS)
    moved = np.abs(data["position"] - scene.initial_positions()).max()
    assert moved > 1e-3  # the fluid fell: under gravity alone 0.5 g t^2 = 2 mm by t = 0.02 s
    assert (data["velocity"][:, 1] < 0).any()


def test_run_prints_summary(tiny_scene_file, tmp_path, capsys):
    out = run_cli(capsys, "run", tiny_scene_file, "--steps", 3, "--out", tmp_path)
    assert "36 particles, 3 steps" in out
    assert str(tmp_path / "final.npz") in out and str(tmp_path / "tiny.pvd") in out


def test_run_vulkan_matches_numba(numba_run, tiny_scene_file, tmp_path, capsys, monkeypatch):
    vulkan_or_skip()
    from sphcore.backends import VulkanBackend

    # collect what the validation layers reported before the backend closes its context
    messages = []
    close = VulkanBackend.close

    def close_and_collect(self):
        messages.extend(self.ctx.validation_messages)
        close(self)

    monkeypatch.setattr(VulkanBackend, "close", close_and_collect)
    run_cli(capsys, "run", tiny_scene_file, "--steps", STEPS, "--out", tmp_path, "--backend", "vulkan",
            "--validation")
    assert messages == [], f"Vulkan validation errors: {messages}"
    scene = Scene.load(tiny_scene_file)
    vulkan = check_run(tmp_path, scene, STEPS)
    numba = np.load(numba_run / "final.npz")
    # Both backends run the same shaders: the numba mirrors follow shaders/sph/*.comp statement
    # by statement in float32, so after 20 steps only rounding (FMA contraction, the order
    # of float sums on the device) separates them.
    np.testing.assert_allclose(vulkan["position"], numba["position"], rtol=0, atol=1e-4)
    np.testing.assert_allclose(vulkan["velocity"], numba["velocity"], rtol=0, atol=1e-2)


def test_run_shipped_scene_by_name(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)  # the name must resolve to scenes/, not to the working folder
    out_dir = tmp_path / "cube"
    run_cli(capsys, "run", "cube_drop_2d", "--steps", 5, "--out", out_dir)
    from sphcore.cli import SCENE_DIR
    scene = Scene.load(SCENE_DIR / "cube_drop_2d.toml")
    data = check_run(out_dir, scene, 5)
    assert data["position"].shape == (900, 2)
    assert json.loads(str(data["scene"]))["name"] == "cube_drop_2d"
    assert not (tmp_path / "runs").exists()


def test_keys_lists_every_key_with_unit(capsys):
    out = run_cli(capsys, "keys")
    lines = {line.split()[0]: line for line in out.splitlines()[1:] if line.strip()}
    keys = dict(schema_keys())
    assert set(lines) == set(keys)
    for dotted, key in keys.items():
        assert f" {key.unit} " in lines[dotted] or not key.unit, dotted
    assert re.search(r"^fluid\.stiffness\s+400\.0\s+m\^2/s\^2\s+\[1, 1e\+08\]", lines["fluid.stiffness"])
    assert re.search(r'^time\.dt\s+"adaptive"\s+s\s', lines["time.dt"])  # the default model's (engineering)
    assert re.search(r"^forces\.gravity\s+\[0\.0, -9\.81\]\s+m/s\^2\s", lines["forces.gravity"])
    assert re.search(r"^fluid\.rest_density\s+1000\.0\s+kg/m\^3\s", lines["fluid.rest_density"])


def test_plot_writes_png(numba_run, capsys):
    pytest.importorskip("matplotlib")
    import matplotlib.image

    png = numba_run / "final.png"
    png.unlink(missing_ok=True)
    out = run_cli(capsys, "plot", numba_run)
    assert str(png) in out
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    image = matplotlib.image.imread(png)
    assert image.ndim == 3 and image.shape[0] > 100 and image.shape[1] > 100
    pixels = image.reshape(-1, image.shape[-1])
    assert len(np.unique(pixels, axis=0)) > 10  # axes, labels, particles, colour bar: not one colour


def test_plot_to_chosen_path(numba_run, tmp_path, capsys):
    pytest.importorskip("matplotlib")
    target = tmp_path / "picture.png"
    run_cli(capsys, "plot", numba_run, "--out", target)
    assert target.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_plot_of_a_run_without_final_state_says_so(tmp_path, capsys):
    assert main(["plot", str(tmp_path)]) == 1
    err = capsys.readouterr().err
    assert "final.npz: no such file" in err and "Traceback" not in err


def test_keys_of_one_section(capsys):
    lines = run_cli(capsys, "keys", "time").splitlines()[1:]
    assert lines and all(line.startswith("time.") for line in lines)
    assert {line.split()[0] for line in lines} == {k for k in dict(schema_keys()) if k.startswith("time.")}
    assert main(["keys", "timing"]) == 1
    assert "no section 'timing' (sections: domain, fluid, forces, physics, time, walls)" in capsys.readouterr().err


def test_version(capsys):
    import sphcore
    with pytest.raises(SystemExit) as stop:
        main(["--version"])
    assert stop.value.code == 0 and capsys.readouterr().out.strip() == f"sphcore {sphcore.__version__}"


def test_unknown_scene_name_lists_the_shipped_scenes(capsys):
    assert main(["run", "dam_brake_2d", "--steps", "1"]) == 1
    err = capsys.readouterr().err
    assert "'dam_brake_2d': no such scene file, and no shipped scene of that name" in err
    assert "dam_break_2d, dam_break_3d" in err and len(err.strip().splitlines()) == 1


def test_control_characters_in_a_name_stay_on_one_line(capsys):
    assert main(["plot", "\x1e"]) == 1
    err = capsys.readouterr().err
    assert err.splitlines() == [err.rstrip("\n")] and err.startswith("sphcore: error: \\x1e/final.npz")
