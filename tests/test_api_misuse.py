"""The Python API misused (issue 30, section 4): a closed Simulation, Ctrl-C inside step(), two threads
on one Simulation, bad arguments to sphcore.run, a Scene changed after it was checked, and
write_snapshot() into a folder a run holds. Each gets a one-line refusal or the safe result, and no
file already written is lost.
"""
import os
import signal
import threading

import numpy as np
import pytest

from conftest import vulkan_or_skip
from sphcore import folder
from sphcore.scene import Scene, SceneError
from sphcore.simulation import Simulation, SimulationError, run

# 8 x 12 = 96 particles against the left wall of a 1 m box (tests/test_resume.py's dam)
SCENE = {
    "name": "dam",
    "physics": {"model": "graphics"},
    "fluid": {"spacing": 0.05, "blocks": [{"min": [0.0, 0.0], "max": [0.4, 0.6]}]},
    "time": {"dt": 1e-3, "steps": 20, "output_every": 10, "checkpoint_every": 10},
}
BACKENDS = ["numba", pytest.param("vulkan", marks=pytest.mark.vulkan)]


def open_simulation(backend, **options):
    if backend == "vulkan":
        vulkan_or_skip()
    return Simulation(Scene.from_dict(SCENE), backend, **options)


def files(out_dir):
    """name -> bytes of every file under `out_dir`."""
    return {str(p.relative_to(out_dir)): p.read_bytes() for p in sorted(out_dir.rglob("*")) if p.is_file()}


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_closed_simulation_raises_on_every_use(backend, tmp_path):
    """After close() (and after a `with` block) every use raises SimulationError saying it is closed: on
    Vulkan step() or read() used to kill the interpreter (rc 139), on numba step() went on."""
    with open_simulation(backend) as sim:
        sim.step(300)  # (more steps than DFSPH's log ring holds, in one call)
        checkpoint = sim.checkpoint()
    uses = {"step": lambda: sim.step(1), "advance": lambda: sim.advance(1), "read": sim.read,
            "checkpoint": sim.checkpoint, "restore": lambda: sim.restore(checkpoint),
            "write_snapshot": lambda: sim.write_snapshot(tmp_path / "snapshots"), "surface": sim.surface,
            "time": lambda: sim.time, "dt": lambda: sim.dt}
    for name, use in uses.items():
        with pytest.raises(SimulationError, match=r"is closed") as e:
            use()
        assert len(str(e.value).splitlines()) == 1 and "dam" in str(e.value), name
    sim.close()  # a second close does nothing
    assert sim.step_count == 300
    assert not (tmp_path / "snapshots").exists()


@pytest.mark.parametrize("backend", BACKENDS)
def test_ctrl_c_inside_step_keeps_the_counters_true(backend, tmp_path):
    """A real SIGINT arrives while step(100) runs its 4th chunk (a step on numba, a submission of
    steps_per_submit = 8 on Vulkan): the chunk completes, step() raises KeyboardInterrupt, and step_count
    and time count the steps that ran; the state is bitwise that of a run of as many steps, and the next
    snapshot is labelled with that step. (It used to say step 0 after 27 steps.)"""
    options = {"steps_per_submit": 8} if backend == "vulkan" else {}
    per_chunk = options.get("steps_per_submit", 1)
    with open_simulation(backend, **options) as sim:
        real_step, chunks = sim.backend.step, []

        def step(count):
            chunks.append(count)
            if len(chunks) == 4:
                os.kill(os.getpid(), signal.SIGINT)  # Ctrl-C, delivered while the chunk runs
            real_step(count)

        sim.backend.step = step
        with pytest.raises(KeyboardInterrupt):
            sim.step(100)
        sim.backend.step = real_step
        assert chunks == [per_chunk] * 4
        ran = 4 * per_chunk
        assert sim.step_count == ran
        assert sim.time == pytest.approx(ran * 1e-3, rel=1e-6)  # (dt as float32 holds it)
        stopped = sim.read()
        path = sim.write_snapshot(tmp_path)
    assert path.name == f"dam_{ran:07d}.vtp"
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # (put back)
    with open_simulation(backend, **options) as sim:
        sim.step(ran)
        expected = sim.read()
    for name in ("particle_x", "particle_v", "particle_rho"):
        assert np.array_equal(stopped[name], expected[name]), name


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_second_thread_is_refused_while_one_steps(backend):
    """While a thread is inside step(), another thread's step(), read() and close() are refused naming the
    conflict (no wait: a non-blocking lock), and the state ends as 5 steps of one thread leave it (two
    threads stepping one state used to turn it NaN, or corrupt the heap on Vulkan)."""
    with open_simulation(backend) as sim:
        real_step, inside, go = sim.backend.step, threading.Event(), threading.Event()

        def step(count):
            inside.set()
            assert go.wait(60)
            real_step(count)

        sim.backend.step = step
        worker = threading.Thread(target=sim.step, args=(5,), name="stepper")
        worker.start()
        try:
            assert inside.wait(60)
            for use in (lambda: sim.step(1), sim.read, sim.close, lambda: sim.time):
                with pytest.raises(SimulationError) as e:
                    use()
                message = str(e.value)
                assert "thread 'stepper' is in Simulation.step()" in message and "MainThread" in message, message
        finally:
            go.set()
            worker.join(60)
        sim.backend.step = real_step
        assert sim.step_count == 5
        shared = sim.read()
    with open_simulation(backend) as sim:
        sim.step(5)
        alone = sim.read()
    assert np.array_equal(shared["particle_x"], alone["particle_x"])


@pytest.mark.parametrize("arguments, message", [
    ({"steps": -5}, "steps must be an integer within [0, 1000000000]"),
    ({"steps": 2.5}, "steps must be an integer"),
    ({"steps": True}, "steps must be an integer"),
    ({"local_size": 0}, "local_size must be an integer within [1, 1024]"),
    ({"local_size": 2048}, "local_size must be an integer within [1, 1024]"),
    ({"local_size": 64.0}, "local_size must be an integer"),
    ({"backend": "cuda"}, "unknown backend 'cuda'"),
    ({"device": 0}, "the numba backend takes no option 'device'"),
    ({"overwrite": "yes"}, "overwrite must be True or False"),
    ({"progress": None}, "progress must be True or False"),
    ({"out_dir": 3}, "out_dir must be a path"),
    ({"scene": SCENE}, "scene must be a sphcore.Scene"),
])
def test_run_refuses_bad_arguments_before_touching_the_folder(tmp_path, arguments, message):
    """Each bad argument of sphcore.run is refused in one line naming it, with overwrite=True, before the
    earlier run in the folder is touched (local_size = 0 used to raise ZeroDivisionError after --overwrite
    had deleted it; steps = -5 "completed" at step 0)."""
    out = tmp_path / "run"
    run(Scene.from_dict(SCENE), "numba", 10, out, progress=False)
    before = files(out)
    call = {"scene": Scene.from_dict(SCENE), "backend": "numba", "steps": 20, "out_dir": out, "progress": False,
            "overwrite": True, **arguments}
    with pytest.raises(ValueError) as e:
        run(**call)
    assert message in str(e.value) and len(str(e.value).splitlines()) == 1
    assert files(out) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]


def test_simulation_refuses_a_local_size_of_zero():
    with pytest.raises(ValueError, match=r"local_size must be an integer within \[1, 1024\].*got 0"):
        Simulation(Scene.from_dict(SCENE), "numba", local_size=0)


def test_a_scene_changed_after_it_was_checked_is_checked_again(tmp_path):
    """A name changed to one with a "/" after Scene.from_dict (files would land outside out_dir) is refused
    by run() and Simulation naming the key, and nothing is written; a change made after the Simulation
    was made does not reach it (it keeps its own checked copy)."""
    scene = Scene.from_dict(SCENE)
    scene.config["name"] = "../escaped"
    for make in (lambda: run(scene, "numba", 10, tmp_path / "run", progress=False),
                 lambda: Simulation(scene, "numba")):
        with pytest.raises(SceneError, match=r"name = '../escaped': must be a file name") as e:
            make()
        assert "changed after it was checked" in str(e.value)
    assert list(tmp_path.iterdir()) == []
    scene = Scene.from_dict(SCENE)
    with Simulation(scene, "numba") as sim:
        scene.config["name"] = "../escaped"
        scene.config["time"]["dt"] = 1.0
        sim.step(1)
        path = sim.write_snapshot(tmp_path / "snapshots")
        assert sim.time == pytest.approx(1e-3)
    assert path == tmp_path / "snapshots" / "dam_0000001.vtp" and path.is_file()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["snapshots"]


def test_write_snapshot_refuses_a_folder_that_is_locked(tmp_path):
    """write_snapshot() takes the folder's lock, as a run does: while a run (here its flock, which a run
    holds from start to end) holds the folder, the snapshot is refused naming the holder, and the run's
    files and series are untouched; once the lock is released, the snapshot is written."""
    out = tmp_path / "run"
    run(Scene.from_dict(SCENE), "numba", 10, out, progress=False)
    before = files(out)
    with Simulation(Scene.from_dict(SCENE), "numba") as sim:
        sim.step(3)
        fd = folder.lock(out)
        try:
            with pytest.raises(folder.FolderError, match=rf"{out}: another sphcore run is writing to this folder "
                                                         rf"\(pid {os.getpid()}\)"):
                sim.write_snapshot(out)
        finally:
            os.close(fd)
        assert files(out) == before
        path = sim.write_snapshot(out)
    assert path == out / "dam_0000003.vtp"
    assert "dam_0000003.vtp" in (out / "dam.pvd").read_text()


# Issue 30, section 6: a blob of water in free fall in an open domain, dt = "auto". Its box (the hash period of the
# open domain's grid: 10 x 20 cells of h) is left after 0.2 s; by 0.6 s the blob is 1.3 m below it.
BLOB = {
    "name": "blob",
    "physics": {"model": "graphics"},
    "domain": {"boundary": "open", "box_min": [0.0, 0.0], "box_max": [0.5, 1.0]},
    "fluid": {"spacing": 0.025, "blocks": [{"min": [0.15, 0.1], "max": [0.35, 0.3]}]},
    "time": {"dt": "auto"},
}
# a soft fluid (c = 1 m/s) starting on the box's floor: its bound on the speed, twice the sound speed plus the
# free-fall speed to that floor (1.4 m/s), is 4.8 m/s, which free fall passes at t = 0.49 s; in an open domain
# nothing stops the fall, and the bound grows with g t
BLOB_SOFT = {
    "name": "soft",
    "physics": {"model": "graphics"},
    "domain": {"boundary": "open", "box_min": [0.0, 0.0], "box_max": [0.5, 1.0]},
    "fluid": {"spacing": 0.025, "blocks": [{"min": [0.15, 0.0], "max": [0.35, 0.1]}], "stiffness": 1.0},
    "time": {"dt": "auto"},
}
BLOB_3D = {
    "name": "blob3d",
    "physics": {"model": "graphics", "dimension": 3},
    "domain": {"boundary": "open", "box_min": [0.0, 0.0, 0.0], "box_max": [0.3, 0.5, 0.3]},
    "fluid": {"spacing": 0.025, "blocks": [{"min": [0.1, 0.1, 0.1], "max": [0.2, 0.2, 0.2]}]},
    "time": {"dt": "auto"},
}


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("blob", [BLOB, BLOB_SOFT, BLOB_3D], ids=["2d", "2d_soft", "3d"])
def test_a_blob_in_free_fall_in_an_open_domain_falls_freely(backend, blob):
    """Checked every 0.05 s to t = 0.6 s (each read runs the blow-up checks), every particle moves within 2 % of
    g t, its density (summed over the neighbours the hashed grid finds: one missed or counted twice shows) stays
    that of the start, and the blob keeps its size, well past the hash period: it was stopped at t = 0.53 s as a
    blow-up, one particle at 52.6 m/s."""
    if backend == "vulkan":
        vulkan_or_skip()
    scene = Scene.from_dict(blob)
    x0 = scene.initial_positions()
    with Simulation(scene, backend) as sim:
        rho0 = sim.read()["particle_rho"]
        chunk = round(0.05 / scene.dt)
        while sim.time < 0.6:
            sim.step(chunk)
            state = sim.read()
            speed = np.linalg.norm(state["particle_v"], axis=1)
            t = sim.time
            assert np.abs(speed / (9.81 * t) - 1).max() < 0.02, (t, speed.min(), speed.max())
            np.testing.assert_allclose(state["particle_rho"], rho0, rtol=2e-3)  # (a pair at r = h comes and goes)
        x = state["particle_x"]
    assert x[:, 1].max() < scene["domain.box_min"][1] - 1.0  # (a metre below the hash period's start)
    np.testing.assert_allclose(x.max(axis=0) - x.min(axis=0), x0.max(axis=0) - x0.min(axis=0), atol=0.05 * scene.h)


def test_the_energy_check_says_which_bound_failed_with_its_figures():
    """One particle at 50 m/s (past twice the sound speed plus the free-fall speed) in a state 2 m lower, whose
    energy fell: the message says that speed and its bound, and that the energy fell, as its figures do (it
    said "rose from 147.8 J to 142.7 J"). Every particle at 10 m/s: the energy rose past its bound."""
    import re

    number = r"(-?[\d.]+(?:e[+-]\d+)?)"  # (as :.4g writes one)
    with Simulation(Scene.from_dict(SCENE), "numba") as sim:
        state = sim.read()
        fast = {k: v.copy() for k, v in state.items()}
        fast["particle_x"][:, 1] -= 2.0
        fast["particle_v"][5] = [0.0, -50.0]
        with pytest.raises(SimulationError) as e:
            sim.check_energy(fast)
        message = str(e.value)
        m = re.search(rf"particle 5 moves at 50 m/s, past the {number} m/s allowed .*while the energy (rose|fell) "
                      rf"from {number} J to {number} J", message)
        assert m, message
        assert float(m.group(1)) < 50 and m.group(2) == "fell" and float(m.group(4)) < float(m.group(3))
        assert "gains energy" not in message
        hot = {k: v.copy() for k, v in state.items()}
        hot["particle_v"][:] = [10.0, 0.0]
        with pytest.raises(SimulationError) as e:
            sim.check_energy(hot)
        m = re.search(rf"the energy rose from {number} J to {number} J, past the {number} J allowed", str(e.value))
        assert m and float(m.group(1)) < float(m.group(3)) < float(m.group(2)), str(e.value)
