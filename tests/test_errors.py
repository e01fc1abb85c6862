"""Every bad input a user can meet ends in one clear message: exit code 1, no traceback.

Scene errors go through `sphcore.cli.main` in this process; missing system pieces (Vulkan
loader, Vulkan driver, shader compiler) need a clean process with a changed environment.
"""
import os
import re
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from conftest import skip_unless_compiler, vulkan_or_skip
from sphcore.cli import main
from sphcore.scene import Scene
from sphcore.simulation import SimulationError, run, stable_dt

# 6 x 6 = 36 particles: every scene below is tiny.
TINY = """\
name = "tiny"
[physics]
model = "graphics"
[fluid]
spacing = 0.05
blocks = [{ min = [0.3, 0.4], max = [0.6, 0.7] }]
[time]
dt = 1e-4
steps = 10
output_every = 5
"""


def write(tmp_path, text, name="scene.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


def cli_error(capsys, *argv):
    """Run `sphcore ARGV` in this process; return its stderr after asserting exit code 1."""
    code = main([str(a) for a in argv])
    err = capsys.readouterr().err
    assert code == 1, err
    assert "Traceback" not in err
    assert "sphcore: error: " in err, err  # after any progress bar
    return err.split("sphcore: error: ", 1)[1]


def cli_subprocess(args, cwd, env=None, executable=sys.executable):
    """Run `python -m sphcore ARGS` in a fresh process with `env` (default: ours)."""
    return subprocess.run([executable, "-m", "sphcore", *map(str, args)], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=300)


def assert_clean_failure(proc, out_dir, *needles):
    """A subprocess run failed as a user should see it: exit 1, each needle in stderr, no
    traceback, and no final state written."""
    assert proc.returncode == 1, proc.stderr
    for needle in needles:
        assert needle in proc.stderr, proc.stderr
    assert "Traceback" not in proc.stderr
    assert not (out_dir / "final.npz").exists()


# ---- scene files ----

def test_malformed_toml_names_file_and_line(tmp_path):
    # a clean process, so that "no traceback" means what the user sees
    path = write(tmp_path, 'name = "x"\n[fluid]\nspacing = 0.05\nstiffness = \n', "broken.toml")
    proc = cli_subprocess(["run", path, "--out", tmp_path / "out"], cwd=tmp_path)
    assert_clean_failure(proc, tmp_path / "out", "broken.toml", "malformed TOML", "line 4")


def test_unknown_key_names_table_and_key(tmp_path, capsys):
    path = write(tmp_path, TINY.replace("[fluid]\n", "[fluid]\nstifness = 3\n"))
    err = cli_error(capsys, "run", path, "--out", tmp_path / "out")
    assert str(path) in err
    assert "fluid" in err and "'stifness'" in err
    assert "stiffness" in err.split("'stifness'", 1)[1]  # the known keys are listed after it
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("table, line, key, range_text", [
    ("fluid", "stiffness = -5.0", "fluid.stiffness", "[1, 1e+08] m^2/s^2"),
    ("fluid", "stiffness = nan", "fluid.stiffness", "[1, 1e+08] m^2/s^2"),
    ("time", "dt = 0.0", "time.dt", "[1e-08, 1] s"),
    ("walls", "restitution = 1.5", "walls.restitution", "[0, 1]"),
], ids=["negative-stiffness", "nan-stiffness", "zero-dt", "restitution-above-1"])
def test_out_of_range_names_dotted_key_and_range(tmp_path, capsys, table, line, key, range_text):
    text = TINY.replace(f"[{table}]\n", f"[{table}]\n{line}\n") if f"[{table}]" in TINY else TINY + f"[{table}]\n{line}\n"
    if line.startswith("dt"):
        text = text.replace("dt = 1e-4\n", "")
    path = write(tmp_path, text)
    err = cli_error(capsys, "run", path, "--out", tmp_path / "out")
    assert str(path) in err
    assert f"{key} = " in err
    assert "must be within" in err and range_text in err


@pytest.mark.parametrize("table, line, expected", [
    ("fluid", 'stiffness = "stiff"', ["fluid.stiffness", "expected a number", "'stiff'"]),
    ("forces", "gravity = [0.0, -9.81, 0.0, 1.0]", ["forces.gravity", "expected [x, y] or [x, y, z]", "m/s^2"]),
    ("forces", "gravity = [0.0, -9.81, 0.0]", ["forces.gravity", "has 3 components but physics.dimension = 2"]),
    ("physics", 'equation_of_state = "stiff"', ["physics.equation_of_state", "'linear', 'tait'"]),
    ("physics", "viscosity = 1", ["physics.viscosity", "expected true or false"]),
    ("time", "steps = 2.5", ["time.steps", "expected an integer"]),
    ("fluid", "blocks = [{ min = [0.3, 0.4] }]", ["fluid.blocks[0]", "exactly the keys min and max"]),
], ids=["string-for-number", "vector-with-4-entries", "3-vector-in-2d", "unknown-eos", "number-for-switch",
        "float-for-int", "block-without-max"])
def test_wrong_type_names_key(tmp_path, capsys, table, line, expected):
    text = TINY if f"[{table}]" in TINY else TINY + f"[{table}]\n"
    name = line.split(" = ")[0]
    text = "\n".join(l for l in text.splitlines() if not l.startswith(f"{name} = ")) + "\n"
    path = write(tmp_path, text.replace(f"[{table}]\n", f"[{table}]\n{line}\n"))
    err = cli_error(capsys, "run", path, "--out", tmp_path / "out")
    assert str(path) in err
    for piece in expected:
        assert piece in err


def test_block_outside_box(tmp_path, capsys):
    path = write(tmp_path, TINY.replace("max = [0.6, 0.7]", "max = [0.6, 1.2]"))
    err = cli_error(capsys, "run", path, "--out", tmp_path / "out")
    assert str(path) in err
    assert "fluid.blocks[0]" in err and "is not inside the box" in err


def test_box_narrower_than_2h(tmp_path, capsys):
    # h = 2 * 0.05 = 0.1 m; a box 0.15 m wide on axis 0 is narrower than 2 h = 0.2 m
    text = TINY.replace("blocks = [{ min = [0.3, 0.4], max = [0.6, 0.7] }]",
                        "blocks = [{ min = [0.0, 0.0], max = [0.1, 0.1] }]")
    path = write(tmp_path, text + "[domain]\nbox_max = [0.15, 1.0]\n")
    err = cli_error(capsys, "run", path, "--out", tmp_path / "out")
    assert str(path) in err
    assert "on axis 0 must exceed 2 h = 0.2 m" in err


def test_non_utf8_file(tmp_path, capsys):
    path = tmp_path / "latin1.toml"
    path.write_bytes('name = "caf\u00e9"\n'.encode("latin-1"))
    err = cli_error(capsys, "run", path, "--out", tmp_path / "out")
    assert str(path) in err and "not UTF-8" in err


def test_missing_file(tmp_path, capsys):
    path = tmp_path / "nowhere.toml"
    err = cli_error(capsys, "run", path, "--out", tmp_path / "out")
    assert str(path) in err and "no such scene file" in err


def test_missing_scene_name(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    err = cli_error(capsys, "run", "no_such_scene_2d")
    assert "no_such_scene_2d" in err and "no such scene file" in err
    assert not (tmp_path / "runs").exists()


# ---- Vulkan and the shader compiler missing ----

def test_no_vulkan_loader(tmp_path):
    fake = tmp_path / "fake"
    (fake / "vulkan").mkdir(parents=True)
    (fake / "vulkan" / "__init__.py").write_text('raise OSError("cannot load library \'libvulkan.so.1\'")\n')
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(fake), *filter(None, [os.environ.get("PYTHONPATH")])])
    path = write(tmp_path, TINY)
    proc = cli_subprocess(["run", path, "--backend", "vulkan", "--out", tmp_path / "out"], tmp_path, env)
    assert_clean_failure(proc, tmp_path / "out", "libvulkan.so.1", "apt-get install libvulkan1", "--backend numba")


def test_no_vulkan_driver(tmp_path):
    # With no ICD manifest the loader (1.3) fails vkCreateInstance with
    # VK_ERROR_INCOMPATIBLE_DRIVER; sphcore turns that into its "no Vulkan driver" message.
    vulkan_or_skip()  # the loader must be there for this to be about the driver
    env = dict(os.environ)
    missing = str(tmp_path / "no_such_icd.json")
    env.update(VK_DRIVER_FILES=missing, VK_ICD_FILENAMES=missing)
    env.pop("VK_ADD_DRIVER_FILES", None)
    path = write(tmp_path, TINY)
    proc = cli_subprocess(["run", path, "--backend", "vulkan", "--out", tmp_path / "out"], tmp_path, env)
    assert_clean_failure(proc, tmp_path / "out", "apt-get install mesa-vulkan-drivers", "--backend numba")
    assert re.search(r"no Vulkan (driver|device)", proc.stderr), proc.stderr


def test_no_shader_compiler(tmp_path):
    vulkan_or_skip()  # the compiler is only looked for once a device is open
    bin_dir = Path(sys.executable).parent
    if any((bin_dir / tool).exists() for tool in ("glslangValidator", "glslc")):
        bin_dir = tmp_path / "bin"
        bin_dir.mkdir()
        (bin_dir / "python3").symlink_to(sys.executable)
    env = dict(os.environ, PATH=str(bin_dir), SPHCORE_CACHE_DIR=str(tmp_path / "cache"))
    (tmp_path / "cache").mkdir()
    assert shutil.which("glslangValidator", path=env["PATH"]) is None
    assert shutil.which("glslc", path=env["PATH"]) is None
    path = write(tmp_path, TINY)
    proc = cli_subprocess(["run", path, "--backend", "vulkan", "--out", tmp_path / "out"], tmp_path, env)
    assert_clean_failure(proc, tmp_path / "out", "no GLSL compiler found", "apt-get install glslang-tools")
    assert not list((tmp_path / "cache").rglob("*.spv"))


def test_shader_compile_error_names_file_and_line(tmp_path, monkeypatch):
    skip_unless_compiler()
    from sphcore.vk_runner import ShaderCompileError, compile_glsl
    monkeypatch.setenv("SPHCORE_CACHE_DIR", str(tmp_path / "cache"))
    source = tmp_path / "broken.comp"
    source.write_text("#version 450\n"
                      "layout(local_size_x = 1) in;\n"
                      "void main() {\n"
                      "    float x = ;\n"  # line 4
                      "}\n")
    with pytest.raises(ShaderCompileError) as info:
        compile_glsl(source)
    message = str(info.value)
    assert str(source.resolve()) in message
    assert f"{source.resolve()}:4:" in message  # glslangValidator and glslc both write FILE:LINE:
    assert not list((tmp_path / "cache").rglob("*.spv"))


def test_out_of_device_memory_names_buffer():
    vulkan_or_skip()
    from sphcore.vk_runner import Context, VulkanError
    ctx = Context()
    try:
        with pytest.raises(VulkanError) as info:
            ctx.buffer(2**44, "huge")
        message = str(info.value)
        assert "out of device memory" in message
        assert "'huge'" in message
        assert "--backend numba" in message
        ctx.buffer(1024, "small").free()  # the context is still usable afterwards
    finally:
        ctx.close()


# ---- the simulation blowing up ----

def blow_up_scene():
    # dt = 0.05 s is 2e4 times the CFL bound 0.25 h / sqrt(k) = 2.5e-6 s; the maximal
    # viscosity makes the velocities grow by about 200x per step, so they overflow to
    # inf/NaN after a dozen steps (step 13 with the numba mirrors).
    return Scene.from_dict({
        "name": "blowup",
        "physics": {"model": "graphics"},
        "fluid": {"spacing": 0.05, "blocks": [{"min": [0.3, 0.4], "max": [0.6, 0.7]}],
                  "stiffness": 1e8, "viscosity": 1e5},
        "time": {"dt": 0.05, "steps": 40, "output_every": 5},
    })


def test_blow_up_names_step_particle_and_bound(tmp_path):
    # Checked every 5 steps; a failed check is replayed step by step from the last good one, so
    # the error names the first bad step. The mirrors may step a NaN state (zero densities,
    # 0 / 0): that must give NaN as on the GPU, not a ZeroDivisionError.
    scene = blow_up_scene()
    dt_max, bound = stable_dt(scene)
    assert bound == "CFL" and scene["time.dt"] > 1000 * dt_max
    with pytest.raises(SimulationError) as info:
        run(scene, "numba", steps=40, out_dir=tmp_path, progress=False)
    message = str(info.value)
    m = re.search(r"blow-up at step (\d+) .*particle (\d+) .*likely cause: time\.dt = 0\.05 s exceeds "
                  r"the CFL bound", message)
    assert m, message
    step, particle = int(m.group(1)), int(m.group(2))
    assert 0 < step < 40 and 0 <= particle < 36
    # the first bad step: one step fewer passes every check
    run(scene, "numba", steps=step - 1, out_dir=tmp_path / "before", progress=False)

    # the snapshots before the blow-up are complete; no final state was written
    assert not (tmp_path / "final.npz").exists()
    pvd = ET.parse(tmp_path / "blowup.pvd").getroot()
    files = [ds.get("file") for ds in pvd.iter("DataSet")]
    assert files == [f"blowup_{s:07d}.vtp" for s in range(0, step, 5)]  # every snapshot before the blow-up
    for name in files:
        piece = ET.parse(tmp_path / name).getroot().find("PolyData/Piece")
        assert piece.get("NumberOfPoints") == "36"
    assert not (tmp_path / f"blowup_{step:07d}.vtp").exists()
    assert not list(tmp_path.glob(".*tmp*"))  # no half-written temporary files


def test_blow_up_through_cli(tmp_path, capsys):
    scene = blow_up_scene()
    path = write(tmp_path, "\n".join([
        'name = "blowup"',
        "[physics]",
        'model = "graphics"',
        "[fluid]",
        "spacing = 0.05",
        "blocks = [{ min = [0.3, 0.4], max = [0.6, 0.7] }]",
        f"stiffness = {scene['fluid.stiffness']}",
        f"viscosity = {scene['fluid.viscosity']}",
        "[time]",
        "dt = 0.05",
        "output_every = 5",
    ]) + "\n")
    err = cli_error(capsys, "run", path, "--steps", 40, "--out", tmp_path / "out")
    assert "blow-up at step" in err and "exceeds the CFL bound" in err
    assert (tmp_path / "out" / "blowup.pvd").exists()
    assert not (tmp_path / "out" / "final.npz").exists()


# ---- command line usage ----

@pytest.mark.parametrize("argv", [
    ["run", "cube_drop_2d", "--steps", "-1"],
    ["run", "cube_drop_2d", "--local-size", "0"],
    ["run", "cube_drop_2d", "--backend", "cuda"],
    ["run"],
    ["frobnicate"],
], ids=["negative-steps", "zero-local-size", "unknown-backend", "no-scene", "unknown-command"])
def test_usage_errors_exit_2(tmp_path, capsys, monkeypatch, argv):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as info:
        main(argv)
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith("usage: sphcore")
    if "-1" in argv:
        assert "--steps must be >= 0, got -1" in err
    assert not (tmp_path / "runs").exists()
