"""Runs measured in simulated seconds (issue 31, section 5): time.end ends a run at the first step whose
time is at or past it, time.output_interval writes a snapshot at the first step at or past each multiple
of it (with the step's time in the .pvd), and a run stopped on the way resumes to the same files.

The expected steps come from the definitions: with a fixed dt the time of step k is k dt; with an
adaptive dt, from a Simulation stepped one step at a time, reading its time after each.
"""
import math
import os
import signal

import numpy as np
import pytest

from sphcore.output import read_pvd, snapshot_step
from sphcore.scene import Scene
from sphcore.simulation import CHECKPOINT, Interrupted, Simulation, resume, run

END, INTERVAL = 0.0405, 0.01  # s
SCENE = {  # test_resume.py's small dam break (96 particles), with the time in seconds
    "name": "dam",
    "physics": {"model": "graphics", "list_skin": 0},
    "fluid": {"spacing": 0.05, "blocks": [{"min": [0.0, 0.0], "max": [0.4, 0.6]}]},
    "time": {"dt": 1e-3, "end": END, "output_interval": INTERVAL, "checkpoint_every": 50},
}


def timed_scene(dt, end=END, interval=INTERVAL):
    return Scene.from_dict({**SCENE, "time": {**SCENE["time"], "dt": dt, "end": end, "output_interval": interval}})


def at(t, target):
    """A time at or past `target`: within a millionth of it counts (k float32 dts fall short of k times a decimal
    dt by its rounding, and a user who asks for 0.005 s at 1e-4 s means 50 steps)."""
    return t >= target * (1 - 1e-6)


def expected(times, end_time=END, interval=INTERVAL):
    """(final step, snapshot steps) for the times of steps 0, 1, 2, ... (times[k] is the time after step k)."""
    end = next(k for k, t in enumerate(times) if at(t, end_time))
    shots = {0, end} | {next(k for k, t in enumerate(times) if at(t, m * interval))
                        for m in range(1, math.ceil(end_time / interval) + 1) if m * interval <= times[end]}
    return end, sorted(shots)


def series(out_dir):
    """[(step, time)] of the run's .pvd."""
    return [(snapshot_step(name), t) for name, t in read_pvd(out_dir / "dam.pvd")]


@pytest.mark.parametrize("dt, end_time, interval, steps, shots", [
    (1e-3, END, INTERVAL, 41, [0, 10, 20, 30, 40, 41]),  # each step just past its multiple: float32(1e-3) > 1e-3
    (2.0**-10, 2.0**-5, 2.0**-7, 32, [0, 8, 16, 24, 32]),  # binary fractions: steps exactly at the multiples
    (1e-4, 0.005, 0.001, 50, [0, 10, 20, 30, 40, 50]),  # float32(1e-4) < 1e-4: each multiple a rounding short
])
def test_fixed_dt_ends_at_the_first_step_past_time_end(dt, end_time, interval, steps, shots, tmp_path):
    """With a fixed dt (float32 in the parameter block) step k is at k dt: the run ends at the first step at or
    past time.end, and writes the first step at or past each multiple of time.output_interval, and the last."""
    times = [k * float(np.float32(dt)) for k in range(100)]
    assert expected(times, end_time, interval) == (steps, shots)
    final = run(timed_scene(dt, end_time, interval), "numba", out_dir=tmp_path, progress=False)
    assert int(final["step"]) == steps and float(final["time"]) == times[steps]
    assert series(tmp_path) == [(k, times[k]) for k in shots]


def adaptive_times(scene, until):
    """The time after each step of `scene`, stepped one at a time, to the first step at or past `until`."""
    times = [0.0]
    with Simulation(scene, "numba") as sim:
        while times[-1] < until:
            sim.step(1)
            times.append(sim.time)
    return times


def test_adaptive_dt_ends_at_the_first_step_past_time_end(tmp_path):
    """With dt chosen on the device each step, the run stops at the step a Simulation stepped one at a time
    first reaches time.end, at the same time to the bit, and its snapshots fall where that Simulation first
    passes each multiple of the interval, with their times in the .pvd."""
    scene = timed_scene("adaptive")
    times = adaptive_times(scene, END)
    end, shots = expected(times)
    assert len(set(np.diff(times[1:end]).round(12))) > 1  # the dt did vary
    final = run(scene, "numba", out_dir=tmp_path, progress=False)
    assert int(final["step"]) == end and float(final["time"]) == times[end]
    assert series(tmp_path) == [(k, times[k]) for k in shots]


@pytest.mark.parametrize("dt", [1e-3, "adaptive"])
def test_a_timed_run_stopped_by_sigint_resumes_to_the_same_files(dt, tmp_path, monkeypatch):
    """SIGINT during the chunk that passes step 15 stops the run there with a checkpoint; resumed, it ends at
    time.end with the same final.npz, checkpoint, .pvd and snapshots as a run never stopped."""
    scene = timed_scene(dt)
    run(scene, "numba", out_dir=tmp_path / "whole", progress=False)
    advance, sent = Simulation.advance, []

    def interrupted(sim, steps):
        if not sent and sim.step_count + steps >= 15:
            sent.append(sim.step_count + steps)
            os.kill(os.getpid(), signal.SIGINT)  # handled by sphcore.run's handler during this chunk
        advance(sim, steps)

    monkeypatch.setattr(Simulation, "advance", interrupted)
    with pytest.raises(Interrupted) as stop:
        run(scene, "numba", out_dir=tmp_path / "stopped", progress=False)
    monkeypatch.setattr(Simulation, "advance", advance)
    assert f"at step {sent[0]} (t = " in str(stop.value) and f"of time.end = {END:g} s" in str(stop.value)
    assert 15 <= int(np.load(tmp_path / "stopped" / CHECKPOINT)["step"]) == sent[0] < 41
    resume(tmp_path / "stopped", progress=False)
    whole, stopped = tmp_path / "whole", tmp_path / "stopped"
    names = sorted(p.name for p in whole.iterdir() if p.suffix in (".npz", ".pvd", ".vtp"))
    assert names == sorted(p.name for p in stopped.iterdir() if p.suffix in (".npz", ".pvd", ".vtp"))
    for name in names:
        assert (stopped / name).read_bytes() == (whole / name).read_bytes(), name
