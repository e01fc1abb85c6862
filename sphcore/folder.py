"""A run owns its output folder: one run at a time holds a lock on it, a new run does not mix its
files with an older run's, and temporary files left by a killed run are removed.

- The lock is flock(2) on the folder itself, held for the whole run and released by the kernel
  when the process ends, however it ends; a second run into the folder is refused naming the
  holder's pid (from /proc/locks).
- A folder holds a run when it has a checkpoint.npz, a final.npz or a snapshot (NAME_NNNNNNN.vtp).
  A new run into it is refused, naming `--resume` and `--overwrite`; with overwrite the older
  run's files (checkpoint.npz, final.npz, final.png, scene.json, *.pvd and *_NNNNNNN.vtp) are
  deleted first, and other files are left alone.
- `.NAME.tmp-PID` files (see sphcore.output.atomic_file) whose process is gone are removed.
"""
import fcntl
import os
import re
from pathlib import Path

from sphcore.scene import SceneError

SNAPSHOT = re.compile(r".+_\d{7}\.vtp$")
RUN_FILES = ("checkpoint.npz", "final.npz", "final.png", "scene.json")
TEMPORARY = re.compile(r"^\..+\.tmp-(\d+)$")


class FolderError(SceneError):
    """An output folder that a run cannot use as it is; the message names the folder and what to do."""


def _holder(path):
    """The pid holding a flock on `path` (from /proc/locks), or None."""
    st = os.stat(path)
    inode = f"{os.major(st.st_dev):02x}:{os.minor(st.st_dev):02x}:{st.st_ino}"
    try:
        for line in Path("/proc/locks").read_text().splitlines():
            fields = line.split()
            if len(fields) > 5 and fields[1] == "FLOCK" and fields[5] == inode:
                return int(fields[4])
    except (OSError, ValueError):
        pass
    return None


def lock(out_dir):
    """Take the folder's lock (creating the folder); return its file descriptor (close it to release)."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    fd = os.open(out_dir, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(fd)
        pid = _holder(out_dir)
        raise FolderError(f"{out_dir}: another sphcore run is writing to this folder ({f'pid {pid}' if pid else 'its pid unknown'}); "
                          "wait for it to end, or give another --out") from None
    return fd


def remove_stale_temporaries(out_dir):
    """Delete the temporary files of processes that no longer exist (a run killed mid-write)."""
    for path in Path(out_dir).iterdir():
        m = TEMPORARY.match(path.name)
        if not m or int(m.group(1)) == os.getpid():
            continue
        try:
            os.kill(int(m.group(1)), 0)
        except ProcessLookupError:
            path.unlink(missing_ok=True)
        except (PermissionError, OverflowError):
            pass  # a live process of another user (or not a pid): leave its file


def run_files(out_dir):
    """The files of a run in `out_dir` (checkpoint, final state, scene, series, snapshots)."""
    out_dir = Path(out_dir)
    return sorted(p for p in out_dir.iterdir() if p.is_file() and (
        p.name in RUN_FILES or p.suffix == ".pvd" or SNAPSHOT.match(p.name)))


def holds_run(out_dir):
    out_dir = Path(out_dir)
    return ((out_dir / "checkpoint.npz").exists() or (out_dir / "final.npz").exists()
            or any(SNAPSHOT.match(p.name) for p in out_dir.iterdir()))


def prepare_new_run(out_dir, overwrite=False):
    """Before a new run (not a resume) into the locked `out_dir`: refuse a folder that holds a run,
    or with `overwrite` delete that run's files."""
    if not holds_run(out_dir):
        return
    if not overwrite:
        raise FolderError(f"{out_dir} holds a run already: continue it with `sphcore run --resume {out_dir}`, "
                          "replace it with --overwrite (its checkpoint, snapshots and final state are deleted), "
                          "or give another --out")
    for path in run_files(out_dir):
        path.unlink(missing_ok=True)
