"""Attacks: sphcore used as a careless or hostile user would (issue 17). Each case is an input and
the one-line refusal, or the safe result, that it must get.

- memory: a run that does not fit is refused before it allocates, with both figures and what
  would fit; the estimate is checked against a measured peak;
- signals at seeded random moments during start-up (while numba compiles) and mid-run: exit
  130/143 every time, every file left loadable;
- a run owns its folder: a second run is refused naming the holder's pid, a used folder is
  refused naming --resume and --overwrite, --overwrite replaces the whole series, stale
  temporaries are removed;
- a checkpoint is untrusted input: each forged field is refused naming it;
- the last tracebacks and silent results of the first round.
"""
import json
import os
import random
import resource
import shutil
import signal
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import numpy as np
import pytest

from conftest import vulkan_or_skip
from sphcore import folder, memory
from sphcore.cli import main
from sphcore.scene import Scene, SceneError
from sphcore.simulation import CHECKPOINT, Simulation, SimulationError, run

ROOT = Path(__file__).resolve().parents[1]
# 6 x 8 = 48 particles: compiles once per process, steps in no time
TOML = """\
name = "tiny"
[physics]
model = "graphics"
[fluid]
spacing = 0.05
blocks = [{ min = [0.1, 0.1], max = [0.4, 0.5] }]
[time]
dt = 1e-3
steps = 20
output_every = 5
checkpoint_every = 10
"""


def one_line_error(argv, capsys, code=1):
    """Run the CLI in this process; assert it failed with `code` and one line, no traceback; return the line."""
    assert main([str(a) for a in argv]) == code
    err = capsys.readouterr().err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    return err.strip()


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """A scene file and a finished run of it (numba, 20 steps) to copy and forge."""
    base = tmp_path_factory.mktemp("tiny")
    (base / "tiny.toml").write_text(TOML)
    assert main(["run", str(base / "tiny.toml"), "--out", str(base / "run")]) == 0
    return base


def loadable(out_dir):
    """Assert every file a run left in `out_dir` loads: npz members, the .pvd and each .vtp it lists."""
    assert not list(out_dir.glob(".*.tmp-*")), list(out_dir.iterdir())
    for npz in out_dir.glob("*.npz"):
        with np.load(npz, allow_pickle=False) as data:
            for name in data.files:
                data[name]
    for pvd in out_dir.glob("*.pvd"):
        for ds in ET.parse(pvd).getroot().iter("DataSet"):
            ET.parse(out_dir / ds.get("file"))
    if (out_dir / "scene.json").exists():
        json.loads((out_dir / "scene.json").read_text())


# ---- 1. memory ----

def test_run_that_does_not_fit_is_refused_with_both_figures(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("SPHCORE_MEMORY_LIMIT", str(450 * 2**20))
    scene = tmp_path / "big.toml"
    scene.write_text(TOML.replace("spacing = 0.05", "spacing = 0.0005"))  # 480,000 particles
    err = one_line_error(["run", scene, "--out", tmp_path / "run"], capsys)
    assert "not enough memory: 480,000 particles (numba, float32) need about" in err, err
    assert "GiB is available (SPHCORE_MEMORY_LIMIT); about" in err and "particles would fit (fluid.spacing = " in err
    assert not (tmp_path / "run" / "scene.json").exists()  # refused before anything was written
    fit = int(err.split("; about ")[1].split()[0].replace(",", ""))
    smaller = Scene.load(scene)
    assert memory.fits(Scene.from_dict({**json.loads(smaller.to_json()), "fluid": {
        **smaller.config["fluid"], "spacing": smaller["fluid.spacing"] * (480_000 / fit) ** 0.5 * 1.01}}))


def test_eight_million_particles_under_three_gigabytes_of_address_space(tmp_path):
    scene = tmp_path / "big.toml"
    scene.write_text(TOML.replace("spacing = 0.05", "spacing = 0.0001").replace("min = [0.1, 0.1]", "min = [0.1, 0.1]")
                     .replace("max = [0.4, 0.5]", "max = [0.5, 0.3]"))  # 4000 x 2000
    limit = 3_000_000_000
    proc = subprocess.run([sys.executable, "-m", "sphcore", "run", str(scene), "--out", str(tmp_path / "run")],
                          capture_output=True, text=True, cwd=ROOT, timeout=120,
                          preexec_fn=lambda: resource.setrlimit(resource.RLIMIT_AS, (limit, limit)))
    assert proc.returncode == 1 and len(proc.stderr.strip().splitlines()) == 1, proc.stderr
    assert "not enough memory: 8,000,000 particles (numba, float32)" in proc.stderr
    assert "(RLIMIT_AS of 2.79 GiB less the " in proc.stderr and "particles would fit" in proc.stderr


def test_estimate_per_backend_and_precision():
    """Derived from sphcore.backends.BUFFERS: float64 doubles the real buffers; Vulkan on a GPU
    keeps its buffers off the host, lavapipe's count; the estimate grows linearly with particles."""
    scene = Scene.load(ROOT / "scenes" / "dam_break_3d.toml")
    f32 = memory.estimate(scene, "numba")[1]
    f64 = memory.estimate(Scene.from_dict({**json.loads(scene.to_json()),
                                           "physics": {**scene.config["physics"], "precision": "float64"}}), "numba")[1]
    assert f32["buffers"] < f64["buffers"] < 2 * f32["buffers"]  # the uint32 buffers stay
    gpu, cpu = memory.estimate(scene, "vulkan")[1], memory.estimate(scene, "vulkan", device_in_host=True)[1]
    assert gpu["buffers"] == 0 and cpu["buffers"] == f32["buffers"] and gpu["staging"] > 0
    n = memory.particle_count(scene)
    per = [memory.estimate(scene, "numba", n=k)[0] for k in (n, 2 * n, 3 * n)]
    assert per[2] - per[1] == per[1] - per[0] > 0


MEASURE = """
import json, sys, tempfile
from pathlib import Path
from sphcore import memory
from sphcore.scene import Scene
from sphcore.simulation import run

backend, precision = sys.argv[2], sys.argv[3]

def scene(spacing):
    return Scene.from_dict({"name": "m", "physics": {"model": "graphics", "precision": precision},
                            "fluid": {"spacing": spacing, "blocks": [{"min": [0, 0], "max": [0.5, 0.5]}]},
                            "time": {"dt": 1e-5, "output_every": 1, "checkpoint_every": 1}})

def status(field):
    return next(int(l.split()[1]) * 1024 for l in open("/proc/self/status") if l.startswith(field + ":"))

with tempfile.TemporaryDirectory() as tmp:
    run(scene(0.05), backend, 1, Path(tmp) / "small", progress=False)  # compiles every kernel
    open("/proc/self/clear_refs", "w").write("5")  # the peak (VmHWM) starts again from here
    before = status("VmRSS")
    big = scene(float(sys.argv[1]))
    run(big, backend, 2, Path(tmp) / "big", progress=False)  # snapshots, checkpoints, final.npz
    total, terms = memory.estimate(big, backend, device_in_host=True)  # lavapipe: device memory is host memory
    print(json.dumps({"growth": status("VmHWM") - before, "estimate": total - terms["compiling"]}))
"""


@pytest.mark.parametrize("backend, precision", [("numba", "float32"), ("numba", "float64"), ("vulkan", "float32")])
def test_estimate_against_the_measured_peak(backend, precision):
    """A 2D run of 250,000 particles after the kernels are compiled: the estimate (less its
    allowance for compiling) is at least the measured growth of the resident set, and at most
    1.5 times it plus 64 MiB: it counts every buffer as resident (untouched zero pages are not)
    and numpy's writer's 16 MiB chunks in full (measured: 1.2 times at 500,000 particles)."""
    if backend == "vulkan":
        vulkan_or_skip()
    proc = subprocess.run([sys.executable, "-c", MEASURE, "0.001", backend, precision], capture_output=True, text=True, cwd=ROOT,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr
    got = json.loads(proc.stdout.strip().splitlines()[-1])
    assert got["growth"] > 50 * 2**20, got  # the run's arrays, not noise
    assert got["growth"] <= got["estimate"] <= 1.5 * got["growth"] + 64 * 2**20, got


def test_vulkan_out_of_memory_suggests_numba_only_where_it_fits(monkeypatch):
    from sphcore.runner import _numba_hint
    from sphcore.vk_runner import VulkanError

    scene = Scene.from_dict({"physics": {"model": "graphics"}, "fluid": {"spacing": 0.0005}})
    error = VulkanError("out of device memory: buffer 'particle_x' needs 9.0 MiB (llvmpipe, heap of 8 MiB); "
                        "use fewer particles or a coarser grid, or --backend numba")
    assert str(_numba_hint(error, scene)) == str(error)
    monkeypatch.setenv("SPHCORE_MEMORY_LIMIT", str(100 * 2**20))
    text = str(_numba_hint(error, scene))
    assert "or --backend numba" not in text and "--backend numba would not fit either" in text
    assert "is available (SPHCORE_MEMORY_LIMIT)" in text


def test_memory_error_mid_run_keeps_the_files(tmp_path, tiny, monkeypatch):
    """A MemoryError anywhere in a run (here: the third snapshot) is a one-line error; files written stay."""
    from sphcore import output

    calls = []
    real_add = output.SnapshotSeries.add

    def add(self, *args, **kw):
        calls.append(1)
        if len(calls) == 3:
            raise MemoryError("Unable to allocate 93.1 GiB")
        return real_add(self, *args, **kw)

    monkeypatch.setattr(output.SnapshotSeries, "add", add)
    with pytest.raises(SimulationError, match=r"^out of memory at step 10 \(Unable to allocate 93.1 GiB\); files "
                                              r"written so far are complete, the checkpoint at step 0 is intact$"):
        run(Scene.load(tiny / "tiny.toml"), "numba", 20, tmp_path, progress=False)
    loadable(tmp_path)
    assert int(np.load(tmp_path / CHECKPOINT)["step"]) == 0 and len(list(tmp_path.glob("*.vtp"))) == 2


# ---- 2. signals during start-up and mid-run ----

SIGNALS = [("start-up", signal.SIGINT, 1), ("start-up", signal.SIGTERM, 2), ("start-up", signal.SIGINT, 3),
           ("mid-run", signal.SIGTERM, 4)]


@pytest.mark.parametrize("when, signum, seed", SIGNALS, ids=[f"{w}-{s.name}-{k}" for w, s, k in SIGNALS])
def test_signal_at_a_random_moment(tmp_path, when, signum, seed):
    """Start-up: the run's folder is locked and the kernels compile (numba: 10-20 s); the signal
    comes 0-6 s after scene.json appears (seeded). Mid-run: 0-1 s after the first checkpoint past
    step 0. Either way: exit 128 + signal, one line, no traceback, every file loadable."""
    delay = random.Random(seed).uniform(0, 6 if when == "start-up" else 1)
    scene = tmp_path / "tiny.toml"
    scene.write_text(TOML.replace("steps = 20", "steps = 1000000").replace("checkpoint_every = 10", "checkpoint_every = 50")
                     .replace('model = "graphics"', 'model = "graphics"\ngravity = false'  # at rest: never blows up
                              + ('\nneighbour_search = "all_pairs"' if when == "mid-run" else "")))  # fewer kernels to compile
    out = tmp_path / "run"
    proc = subprocess.Popen([sys.executable, "-m", "sphcore", "run", str(scene), "--out", str(out)], cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        deadline = time.monotonic() + 180
        while time.monotonic() < deadline and proc.poll() is None:
            if when == "start-up" and (out / "scene.json").exists():
                break
            if when == "mid-run" and (out / CHECKPOINT).exists():
                try:
                    if int(np.load(out / CHECKPOINT)["step"]) > 0:
                        break
                except (OSError, ValueError, KeyError):
                    pass
            time.sleep(0.01)
        time.sleep(delay)
        proc.send_signal(signum)
        _, err = proc.communicate(timeout=120)
    finally:
        proc.kill()
    assert proc.returncode == 128 + signum, err
    last = err.strip().splitlines()[-1].split("\r")[-1]
    assert "Traceback" not in err and last.startswith(f"sphcore: interrupted by {signum.name}"), err
    loadable(out)
    if (out / CHECKPOINT).exists():  # a checkpoint at the step reached: the run resumes
        assert "continue with `sphcore run --resume" in last


# ---- 3. a run owns its folder ----

def test_second_run_into_a_locked_folder_is_refused(tmp_path, capsys):
    (tmp_path / "tiny.toml").write_text(TOML)
    fd = folder.lock(tmp_path / "run")  # as a run in progress holds it
    try:
        err = one_line_error(["run", tmp_path / "tiny.toml", "--out", tmp_path / "run"], capsys)
    finally:
        os.close(fd)
    assert f"{tmp_path / 'run'}: another sphcore run is writing to this folder (pid {os.getpid()})" in err
    assert not (tmp_path / "run" / "scene.json").exists()


def test_used_folder_is_refused_and_overwrite_replaces_the_series(tmp_path, tiny, capsys):
    out = tmp_path / "run"
    shutil.copytree(tiny / "run", out)
    (out / ".checkpoint.npz.tmp-999999999").write_bytes(b"half")  # left by a killed run
    (out / "notes.txt").write_text("mine")
    shorter = tmp_path / "shorter.toml"
    shorter.write_text(TOML.replace("steps = 20", "steps = 5").replace("max = [0.4, 0.5]", "max = [0.4, 0.3]"))
    err = one_line_error(["run", shorter, "--out", out], capsys)
    assert f"{out} holds a run already: continue it with `sphcore run --resume {out}`, replace it with --overwrite" in err
    assert main(["run", str(shorter), "--out", str(out), "--overwrite"]) == 0
    capsys.readouterr()
    steps = [ds.get("file") for ds in ET.parse(out / "tiny.pvd").getroot().iter("DataSet")]
    assert steps == ["tiny_0000000.vtp", "tiny_0000005.vtp"]  # none of the older run's 20 steps
    assert sorted(p.name for p in out.glob("*.vtp")) == steps
    assert not (out / ".checkpoint.npz.tmp-999999999").exists() and (out / "notes.txt").read_text() == "mine"
    assert len(np.load(out / "final.npz")["position"]) == 24
    loadable(out)


# ---- 4. a checkpoint is untrusted input ----

def forge(path, **changes):
    """Rewrite checkpoint `path` with members replaced (a value) or removed (None)."""
    with np.load(path, allow_pickle=False) as data:
        arrays = {name: data[name] for name in data.files}
    for name, value in changes.items():
        if value is None:
            arrays.pop(name)
        else:
            arrays[name] = value
    np.savez(path, **arrays)


def huge_header(path):
    """buffer_particle_x's .npy header claims 25e9 floats (a 93 GiB allocation if believed)."""
    forge(path, buffer_particle_x=None)
    header = {"descr": "<f4", "fortran_order": False, "shape": (6_250_000_000, 4)}
    with zipfile.ZipFile(path, "a") as archive, archive.open("buffer_particle_x.npy", "w") as f:
        np.lib.format.write_array_header_1_0(f, header)
        f.write(b"\0" * 64)


def ids(path):
    with np.load(path) as data:
        values = data["buffer_particle_id"].copy()
    values[1] = values[0]
    return values


FORGERIES = {
    "backend": (lambda p: forge(p, backend=np.array("cuda")), "field backend: 'cuda' names no backend"),
    "negative step": (lambda p: forge(p, step=np.int64(-5)), "field step: -5 is outside [0, 1000000000]"),
    "ids": (lambda p: forge(p, buffer_particle_id=ids(p)), "field buffer_particle_id: is not a permutation of 0..47"),
    "energy bound": (lambda p: forge(p, energy_start=np.float64(1e30)),
                     "checkpoint field energy_start = 1e+30 J is not the energy of the scene's initial state"),
    "huge header": (huge_header, "field buffer_particle_x: is float32[6250000000, 4], this scene needs float32[48, 4]"),
    "object array": (lambda p: forge(p, buffer_particle_v=np.array([None] * 48, object)),
                     "field buffer_particle_v: is object[48], this scene needs float32[48, 4]"),
    "not finite": (lambda p: forge(p, buffer_particle_v=np.full((48, 4), np.nan, np.float32)),
                   "field buffer_particle_v: holds values that are not finite"),
    "outside": (lambda p: forge(p, buffer_particle_x=np.full((48, 4), 7.0, np.float32)),
                "field buffer_particle_x: 48 position(s) outside the box"),
    "missing": (lambda p: forge(p, buffer_particle_rho=None), "field buffer_particle_rho: missing"),
}


@pytest.mark.parametrize("case", FORGERIES)
def test_forged_checkpoint_is_refused_naming_the_field(tmp_path, tiny, capsys, case):
    out = tmp_path / "run"
    shutil.copytree(tiny / "run", out)
    make, says = FORGERIES[case]
    make(out / CHECKPOINT)
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    err = one_line_error(["run", "--resume", out, "--steps", 30], capsys)
    assert says in err, err
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before  # nothing overwritten


def test_resumed_energy_bound_is_the_scenes(tmp_path, tiny):
    """The bound of a resumed run is recomputed from the scene's initial state: the same as the
    uninterrupted run's, whatever the file says."""
    with Simulation(Scene.load(tiny / "tiny.toml")) as sim:
        sim.read()
        expected = sim.energy_start
    with np.load(tiny / "run" / CHECKPOINT) as data:
        assert float(data["energy_start"]) == expected


# ---- 5. the last tracebacks and silent results ----

def test_validate_t_end_inf(tmp_path, capsys):
    with pytest.raises(SystemExit) as stop:
        main(["validate", "dam-break", "--out", str(tmp_path), "--t-end", "inf"])
    assert stop.value.code == 2
    assert "--t-end: invalid positive float value: 'inf'" in capsys.readouterr().err


@pytest.mark.parametrize("content", ["truncated", "object"])
def test_plot_of_a_bad_final_state(tmp_path, tiny, capsys, content):
    shutil.copytree(tiny / "run", tmp_path / "run")
    final = tmp_path / "run" / "final.npz"
    if content == "truncated":
        final.write_bytes(final.read_bytes()[:3000])
    else:
        np.savez(final, position=np.array([None, 1], object), scene=np.array("{}"))
    err = one_line_error(["plot", tmp_path / "run"], capsys)
    assert f"{final}: not a readable final state" in err


def test_render_level_nan(tmp_path, capsys):
    with pytest.raises(SystemExit) as stop:
        main(["render", str(tmp_path), "--level", "nan"])
    assert stop.value.code == 2 and "--level must be a finite number, got nan" in capsys.readouterr().err


def test_run_dev_zero(capsys):
    err = one_line_error(["run", "/dev/zero"], capsys)
    assert "/dev/zero: larger than 1024 KiB: not a scene file" in err


def test_huge_string_in_a_numeric_key_is_not_echoed():
    with pytest.raises(SceneError) as e:
        Scene.from_dict({"fluid": {"spacing": "9" * 100_000_000}})
    assert len(str(e.value)) < 200 and str(e.value).startswith("fluid.spacing: expected a number (m), got '999")


def test_overlapping_blocks_are_refused_naming_both():
    block = {"min": [0.1, 0.1], "max": [0.4, 0.4]}
    with pytest.raises(SceneError, match=r"^fluid\.blocks\[0\] = .* and fluid\.blocks\[1\] = .* overlap"):
        Scene.from_dict({"fluid": {"blocks": [block, block]}})
    Scene.from_dict({"fluid": {"blocks": [block, {"min": [0.4, 0.1], "max": [0.6, 0.4]}]}})  # touching is fine


def test_blow_up_hint_names_the_key_that_sets_dt(tiny):
    """With a fixed dt the hint names time.dt; with dt = "auto", time.dt_fraction."""
    for dt, key in ((1e-3, "lower time.dt "), ("auto", "lower time.dt_fraction ")):
        scene = Scene.from_dict({**json.loads(Scene.load(tiny / "tiny.toml").to_json()),
                                 "time": {"dt": dt, "steps": 20}})
        with Simulation(scene) as sim:
            state = sim.read()
            state["particle_v"][:] = 50.0  # past twice the sound speed plus free fall: an explosion
            with pytest.raises(SimulationError, match=key):
                sim.check_energy(state)


def test_resume_drops_the_snapshots_past_its_checkpoint(tmp_path, tiny, capsys):
    """Killed after snapshot 20 but before its checkpoint: resumed from step 10 to 15, the series
    ends at 15 (the old run's 20 is neither listed nor left)."""
    out = tmp_path / "run"
    shutil.copytree(tiny / "run", out)
    assert main(["run", str(tiny / "tiny.toml"), "--out", str(tmp_path / "ten"), "--steps", "10"]) == 0
    shutil.copy(tmp_path / "ten" / CHECKPOINT, out / CHECKPOINT)
    (out / "final.npz").unlink()
    assert main(["run", "--resume", str(out), "--steps", "15"]) == 0
    capsys.readouterr()
    listed = [ds.get("file") for ds in ET.parse(out / "tiny.pvd").getroot().iter("DataSet")]
    assert listed == [f"tiny_{k:07d}.vtp" for k in (0, 5, 10, 15)]
    assert sorted(p.name for p in out.glob("*.vtp")) == listed
    loadable(out)
