"""Run a scene on a backend: step, check, write snapshots, checkpoints and the final state; resume.

A run survives being stopped: every time.checkpoint_every steps (and at the start, at the end,
and where SIGINT or SIGTERM stops it) DIR/checkpoint.npz holds what `resume` needs to continue
to bitwise the same final state as a run that was never stopped, on the same backend and device.
Every file is written to a temporary name and renamed, so a reader (or a resume) never sees
half of one.
"""
import json
import math
import os
import re
import signal
import sys
import zipfile
from collections.abc import Mapping
from pathlib import Path

import numpy as np
from tqdm import tqdm

from sphcore import folder, memory
from sphcore.backends import check_options
from sphcore.checkpoint import CARRIED, CHECKPOINT, MAX_STEP, read_checked, read_scene
from sphcore.errors import CheckpointError, CheckpointFieldError, Interrupted, SimulationError, VulkanError
from sphcore.gauges import GaugeFiles
from sphcore.output import SnapshotSeries, vtp_bytes
from sphcore.scene import Scene, read_limited
from sphcore.signals import Signals
from sphcore.sph.dfsph import CONTROL_BUILDS
from sphcore.stepper import Simulation


def final_arrays(sim, state, params=None):
    """The arrays of final.npz: state (position, velocity, density, pressure) and the parameters (`params`, by
    default the simulation's)."""
    params = sim.params if params is None else params
    arrays = {
        "position": state["particle_x"],
        "velocity": state["particle_v"],
        "density": state["particle_rho"],
        "pressure": state["particle_p"],
        "step": np.int64(sim.step_count),
        "time": np.float64(sim.time),
        "dt": np.float64(sim.dt),
        "scene": np.array(sim.scene.to_json()),
        "mass": np.float64(sim.scene.mass),
        "h": np.float64(sim.scene.h),
    }
    for field in params.dtype.names:
        arrays[f"param_{field}"] = np.asarray(params[0][field])
    if sim.spec.LIST_SKIN:  # reused lists: their builds since the start (the start's own included)
        arrays["list_builds"] = np.int64(sim.backend.read_buffer("control")[CONTROL_BUILDS])
    arrays.update(sim.solver.final_arrays())  # DFSPH: each step's dt, time, iterations and final errors
    return arrays


def run(scene, backend="numba", steps=None, out_dir=None, progress=True, checkpoint=None, overwrite=False,
        **backend_options):
    """Run `scene` for `steps` steps in all (default: the scene's time.steps, or where it gives time.end,
    to the first step whose simulated time is at or past it), writing snapshots (VTK .vtp + .pvd),
    checkpoints and final.npz to `out_dir`; return the final arrays. `checkpoint`: arrays of
    load_checkpoint to start from (see `resume`).

    The run holds a lock on `out_dir` throughout (sphcore.folder): a second run into it is
    refused. A new run into a folder that holds a run is refused unless `overwrite`, which deletes
    that run's files first. A run that would not fit in memory is refused before it allocates
    (sphcore.memory); running out of memory all the same raises SimulationError, files kept.

    Snapshots go out every time.output_every steps (or at the first step at or past each multiple of
    time.output_interval, with the step's time in the .pvd) and at the end; checkpoints at the start,
    every time.checkpoint_every steps and at the end. A blow-up raises SimulationError after
    the last good snapshot; SIGINT or SIGTERM raises Interrupted after a checkpoint at the step
    reached; a Vulkan failure raises VulkanError naming the checkpoint to resume from. Files
    already written are kept.

    >>> import os, tempfile, sphcore
    >>> out = tempfile.mkdtemp()
    >>> final = sphcore.run(sphcore.Scene.from_dict({"fluid": {"spacing": 0.05}}), steps=20, out_dir=out,
    ...                     progress=False)
    >>> int(final["step"]), final["position"].shape
    (20, (36, 2))
    >>> sorted(f for f in os.listdir(out) if not f.startswith("sphcore-"))
    ['checkpoint.npz', 'final.npz', 'scene.json', 'scene.pvd', 'scene_0000000.vtp', 'scene_0000020.vtp']
    """
    scene, steps, out_dir = _run_arguments(scene, backend, steps, out_dir, progress, checkpoint, overwrite,
                                           backend_options)  # each checked before the folder is touched
    memory.check(scene, backend)  # before the folder is touched (Simulation checks again, with the device)
    if checkpoint is not None and steps is not None and steps < int(checkpoint["step"]):
        raise CheckpointError(f"{out_dir / CHECKPOINT} is at step {int(checkpoint['step'])}, past the {steps} "
                              f"steps asked for: give --steps {int(checkpoint['step'])} or more")
    schedule = Schedule(scene, steps)
    with Signals() as signals, folder.RunFolder(out_dir) as run_folder:  # locked; writes only its own files
        folder.remove_stale_temporaries(out_dir)
        run_folder.prepare(scene["name"], resume=checkpoint is not None, overwrite=overwrite)
        signals.poll()
        if checkpoint is None:
            run_folder.write_bytes("scene.json", scene.to_json().encode())  # what render and resume read
        try:
            series = SnapshotSeries(out_dir, scene["name"], folder=run_folder)
        except (SyntaxError, ValueError) as e:  # xml.etree's ParseError is a SyntaxError
            raise SimulationError(f"{out_dir / scene['name']}.pvd: not a readable ParaView collection ({e}); move "
                                  "it away, or write to another folder") from None
        try:
            sim = Simulation(scene, backend, poll=signals.poll, **backend_options)
        except VulkanError as e:
            raise _numba_hint(e, scene) from None
        except MemoryError as e:
            raise SimulationError(f"out of memory while starting the run ({e}); nothing to resume") from None
        signals.poll()
        saved = None  # the step of the last checkpoint written or resumed from
        files = None  # the gauges' CSV files (scene [[gauges]])

        def write_gauges():
            if files is not None:
                files.add(sim.take_gauge_rows())
                files.write()

        def snapshot(state):
            write_gauges()
            series.add(sim.step_count, sim.time, state["particle_x"], {
                "velocity": state["particle_v"], "density": state["particle_rho"],
                "pressure": state["particle_p"]})

        def save_checkpoint():
            nonlocal saved
            write_gauges()  # (before the checkpoint: a resume keeps the rows it counted, and drops any later)
            run_folder.savez(CHECKPOINT, **sim.checkpoint())
            saved = sim.step_count

        try:
            if checkpoint is not None:
                sim.restore(checkpoint)
                saved = sim.step_count
                series.truncate(sim.step_count)  # snapshots past the checkpoint: of steps that will run again
                note_resume(checkpoint, sim, out_dir)
            if sim.gauges is not None:  # (resumed: the rows the checkpoint counted are kept, later ones dropped)
                taken = checkpoint["gauge_state"][1::2, 1] if checkpoint is not None and "gauge_state" in checkpoint \
                    else None
                files = GaugeFiles(run_folder, scene, taken)
            state = sim.read()
            if checkpoint is None and sim.n > sim.fluid_count:  # the bodies' wall particles: fixed, written once
                run_folder.write_bytes("walls.vtp", vtp_bytes(sim.walls["particle_x"], {"body": sim.walls["body"]}))
            if checkpoint is None:
                snapshot(state)
                save_checkpoint()
            signals.stepping = True
            t = schedule.time(sim)
            with schedule.progress(sim, t, disable=not progress, desc=f"{scene['name']} [{backend}]") as bar:
                while not schedule.done(sim, t) and not signals.received:
                    k = schedule.next_chunk(sim, t)
                    sim.advance(k)
                    sim.build_lists_next()  # (a step where the loop may stop, on a signal too: see there)
                    before, t = t, schedule.time(sim)
                    bar.update(k if schedule.end_time is None else min(t, schedule.end_time) - before)
                    if schedule.snapshot_due(sim, before, t):
                        state = None  # the previous state's arrays are freed before the next read
                        state = sim.read()
                        snapshot(state)
                    if schedule.checkpoint_due(sim) or schedule.done(sim, t) or signals.received:
                        save_checkpoint()
                if signals.received and not schedule.done(sim, t):
                    if saved != sim.step_count:
                        save_checkpoint()
                    raise Interrupted(signals.received, f"interrupted by {signal.Signals(signals.received).name} "
                                      f"at step {sim.step_count} {schedule.of(sim)}; checkpoint written: continue "
                                      f"with `sphcore run --resume {out_dir}`")
            write_gauges()
            arrays = final_arrays(sim, state)
            run_folder.savez("final.npz", **arrays)
        except BaseException as e:
            _count_validation(sim)
            try:
                sim.close()
            except Exception:
                pass  # a lost device fails to close too: the first error is the one to report
            if isinstance(e, VulkanError) and saved is not None:
                cpu = " (add --backend numba to continue on the CPU)" if memory.fits(scene, "numba") else ""
                raise _numba_hint(VulkanError(f"{e}; the checkpoint at step {saved} is intact: continue with "
                                              f"`sphcore run --resume {out_dir}`{cpu}"), scene) from None
            if isinstance(e, MemoryError):
                kept = f"the checkpoint at step {saved} is intact" if saved is not None else "nothing to resume"
                raise SimulationError(f"out of memory at step {sim.step_count} ({e}); files written so far are "
                                      f"complete, {kept}") from None
            raise
        _count_validation(sim)
        sim.close()
        return arrays


ROUNDING = 1e-6  # a time within this fraction of its target has reached it: steps times a float32 dt fall short
#                  of a decimal time by its rounding (8000 steps of 1e-4 s end at 0.79999998 s)


def reached(t, target):
    """Whether simulated time `t` is at or past `target` (within ROUNDING of it)."""
    return t >= target - ROUNDING * abs(target)


class Schedule:
    """Where a run ends (`steps` in all, or with steps None the first step at or past time.end) and which
    steps write: a snapshot every time.output_every steps, or at the first step at or past each multiple of
    time.output_interval; a checkpoint every time.checkpoint_every steps. Each chunk of steps the run loop
    asks for ends where one of these may fall. Times are Simulation.time; each step's dt is at most the
    parameter block's (P.dt: the step where dt is fixed, its cap where it is adaptive: choose_dt.comp)."""

    def __init__(self, scene, steps):
        self.steps, self.end_time = steps, scene.end_time if steps is None else None
        self.every, self.interval = scene["time.output_every"], scene.output_interval
        self.checkpoint_every = scene["time.checkpoint_every"]
        self.chunk = max(1, min(self.every or 50, 50))
        self.timed = self.end_time is not None or self.interval is not None  # the loop follows the time

    def time(self, sim):
        """The simulated time where the schedule follows it (a readback where dt is adaptive), else None."""
        return sim.time if self.timed else None

    def progress(self, sim, t, **options):
        """The progress bar: in steps, or in simulated seconds toward time.end."""
        if self.end_time is None:
            return tqdm(total=self.steps, initial=sim.step_count, unit="step", **options)
        return tqdm(total=self.end_time, initial=min(t, self.end_time), unit="s", **options,
                    bar_format="{l_bar}{bar}| {n:.3f}/{total:.3g} s [{elapsed}<{remaining}]")

    def of(self, sim):
        """Where the run stands against its end, for a message: "of 400", "(t = 0.5 s) of 1 s"."""
        if self.end_time is None:
            return f"of {self.steps}"
        return f"(t = {sim.time:.6g} s) of time.end = {self.end_time:g} s"

    def done(self, sim, t):
        return sim.step_count >= self.steps if self.end_time is None else reached(t, self.end_time)

    def next_output(self, t):
        """The multiple of time.output_interval that the next snapshot waits for (the first past t)."""
        m = math.floor(t / self.interval) + 1
        while reached(t, m * self.interval):  # (t / interval rounded down across a whole number)
            m += 1
        return m * self.interval

    def next_chunk(self, sim, t):
        """The steps to run next: none past the end, a snapshot's step or a checkpoint's."""
        n = sim.step_count
        k = min(self.chunk, self.checkpoint_every - n % self.checkpoint_every)
        k = min(k, self.steps - n) if self.end_time is None else min(k, steps_toward(sim, self.end_time, t))
        if self.every:
            k = min(k, self.every - n % self.every)
        if self.interval is not None:
            k = min(k, steps_toward(sim, self.next_output(t), t))
        return k

    def snapshot_due(self, sim, before, t):
        """Whether the chunk that took the time from `before` to `t` ends at a snapshot's step."""
        return bool(self.every and sim.step_count % self.every == 0 or self.done(sim, t)
                    or self.interval is not None and reached(t, self.next_output(before)))

    def checkpoint_due(self, sim):
        return sim.step_count % self.checkpoint_every == 0


def steps_toward(sim, target, t):
    """Steps to run from simulated time `t` toward `target` that end at the first step at or past it, or
    before it: where dt is fixed, exactly those to the first step at or past it (the time is steps times
    dt); where it is adaptive, as many as cannot reach it at the cap P.dt, with a step to spare (the
    device's sum of float32 dts), at least 1: the last steps before `target` run one at a time."""
    dt = float(sim.params[0]["dt"])
    if sim.scene.adaptive_dt:
        return max(1, int((target - t) / dt) - 1)
    k = max(1, math.ceil((target - t) / dt))
    while k > 1 and reached((sim.step_count + k - 1) * dt, target):
        k -= 1
    while not reached((sim.step_count + k) * dt, target):
        k += 1
    return k


def _run_arguments(scene, backend, steps, out_dir, progress, checkpoint, overwrite, backend_options):
    """run()'s arguments checked, before anything is deleted or written: (the scene checked again, a
    copy: Scene.validated; the steps, None to run to the scene's time.end; the folder). A bad one
    raises ValueError (SceneError for the scene) naming it."""
    if not isinstance(scene, Scene):
        raise ValueError(f"scene must be a sphcore.Scene (Scene.load or Scene.from_dict), got {type(scene).__name__}")
    scene = scene.validated()
    check_options(backend, backend_options)
    to_end = steps is None and scene.end_time is not None  # steps None: to time.end
    steps = scene["time.steps"] if steps is None and not to_end else steps
    if not to_end and (isinstance(steps, bool) or not isinstance(steps, (int, np.integer))
                       or not 0 <= steps <= MAX_STEP):
        raise ValueError(f"steps must be an integer within [0, {MAX_STEP}] (the steps in all, counted from the run's "
                         f"start), got {steps!r}")
    if out_dir is not None and not isinstance(out_dir, (str, os.PathLike)):
        raise ValueError(f"out_dir must be a path (str or os.PathLike), got {type(out_dir).__name__}")
    for name, value in (("progress", progress), ("overwrite", overwrite)):
        if not isinstance(value, (bool, np.bool_)):
            raise ValueError(f"{name} must be True or False, got {value!r}")
    if checkpoint is not None and not (isinstance(checkpoint, Mapping) and "step" in checkpoint):
        raise ValueError("checkpoint must be the arrays of load_checkpoint (a mapping with a step), got "
                         f"{type(checkpoint).__name__}")
    return scene, None if to_end else int(steps), Path(out_dir or Path("runs") / scene["name"])


def _count_validation(sim):
    """With the Vulkan validation layers on, say how many errors they reported (each was printed as it came)."""
    ctx = getattr(sim.backend, "ctx", None)
    if getattr(ctx, "validation", False):
        count = len(ctx.validation_messages)
        print(f"sphcore: {count} Vulkan validation error(s){' (printed above)' if count else ''}", file=sys.stderr)


def _numba_hint(error, scene):
    """`error` (a VulkanError) with its "--backend numba" suggestion kept only where a numba run of
    `scene` would fit in memory; else the suggestion gives way to the figures."""
    text = str(error)
    if "--backend numba" not in text:
        return error
    try:
        memory.check(scene, "numba")
        return error
    except memory.MemoryLimitError as e:
        text = re.sub(r",? or (run with )?--backend numba", "", text)
        return VulkanError(f"{text} (--backend numba would not fit either: {str(e).split(': ', 1)[1]})")


def load_checkpoint(out_dir):
    """(scene, checkpoint arrays) of the run in `out_dir`: the scene of out_dir/scene.json, which
    must be the one the checkpoint was computed with and give the same parameter block."""
    out_dir = Path(out_dir)
    path, scene_file = out_dir / CHECKPOINT, out_dir / "scene.json"
    if not path.is_file():
        raise CheckpointError(folder.missing_checkpoint(out_dir, CHECKPOINT))
    try:
        stored_scene = json.loads(read_scene(path))
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as e:  # JSONDecodeError is a ValueError
        raise CheckpointError(f"{path}: not a readable checkpoint ({e})") from None
    try:
        scene = Scene.from_dict(json.loads(read_limited(scene_file)), str(scene_file))
    except (OSError, ValueError) as e:  # SceneError, JSONDecodeError and UnicodeDecodeError are ValueErrors
        raise CheckpointError(f"{scene_file}: {getattr(e, 'strerror', None) or e}; the run's scene is needed "
                              "to resume") from None
    difference = _first_difference(scene.config, stored_scene)
    if difference:
        raise CheckpointError(f"{scene_file} is not the scene {path} was computed with ({difference}); "
                              "put the run's scene back, or start a new run in another folder")
    n = scene.fluid_count()
    try:
        arrays = read_checked(path, scene, scene.params(n), CARRIED)
    except CheckpointFieldError as e:
        raise CheckpointError(f"{path}: checkpoint {e}; refused") from None
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as e:
        raise CheckpointError(f"{path}: not a readable checkpoint ({e})") from None
    params = scene.params(n)
    if arrays["params"].tobytes() != params.tobytes():
        stored = np.frombuffer(arrays["params"].tobytes(), params.dtype) if arrays["params"].nbytes == params.nbytes else None
        field = "layout" if stored is None else next((f for f in params.dtype.names
                                                      if stored[0][f].tobytes() != params[0][f].tobytes()), "padding")
        raise CheckpointError(f"{path}: the parameter block this version of sphcore computes from the scene differs "
                              f"from the checkpoint's (field {field}): written by another version; "
                              "start a new run")
    return scene, arrays


def _first_difference(a, b, where=""):
    """'key: x here, y there' for the first dotted key whose values differ, else ''."""
    if isinstance(a, dict) and isinstance(b, dict):
        for name in sorted(set(a) | set(b)):
            found = _first_difference(a.get(name), b.get(name), f"{where}.{name}" if where else name)
            if found:
                return found
        return ""
    return "" if a == b else f"{where} = {json.dumps(a)} in scene.json, {json.dumps(b)} in the checkpoint"


def note_resume(checkpoint, sim, out_dir):
    """Say so on stderr where a resumed run continues on another backend or device than the one
    that wrote its checkpoint: it continues from the same state, but not to the same bits."""
    then = (str(checkpoint["backend"]), str(checkpoint["device"]))
    now = (sim.backend.name, sim.device_name)
    if then != now:
        print(f"sphcore: note: {out_dir}/{CHECKPOINT} was written by {then[0]} on {then[1]}; continuing on "
              f"{now[0]} on {now[1]}: the final state will not be bitwise that of an uninterrupted run",
              file=sys.stderr)


def resume(out_dir, backend=None, steps=None, progress=True, **backend_options):
    """Continue the run in `out_dir` from its checkpoint until it has `steps` steps in all (default:
    the scene's time.steps, or its time.end), on `backend` (default: the one that wrote the checkpoint). The
    snapshot series continues; with the same backend and device the final state is bitwise that
    of a run never stopped.

    >>> import tempfile, sphcore
    >>> out = tempfile.mkdtemp()
    >>> scene = sphcore.Scene.from_dict({"fluid": {"spacing": 0.05}})
    >>> _ = sphcore.run(scene, steps=20, out_dir=out, progress=False)
    >>> int(sphcore.resume(out, steps=40, progress=False)["step"])  # 20 steps more
    40
    """
    scene, checkpoint = load_checkpoint(out_dir)
    return run(scene, backend or str(checkpoint["backend"]), steps, out_dir, progress, checkpoint=checkpoint,
               **backend_options)
