"""A run owns its output folder: one run at a time holds a lock on it, a run writes and deletes only
the files it wrote itself (its manifest lists them), and temporary files left by a killed run are
removed.

- The lock is flock(2) on the folder itself, held for the whole run and released by the kernel
  when the process ends, however it ends; a second run into the folder is refused naming the
  holder's pid (from /proc/locks).
- The manifest, DIR/sphcore-run.json, lists every file a run (and `sphcore plot`, `--profile`)
  wrote there; it is rewritten (atomically) before each new file is written, so it never misses
  one. The names a run writes: scene.json, checkpoint.npz, final.npz, walls.vtp (the bodies' wall particles),
  NAME.pvd, NAME_NNNNNNN.vtp (NAME: the scene's name), a run on several ranks' NAME_NNNNNNN.pvtp and its pieces
  NAME_NNNNNNN_pR.vtp (sphcore.parallel), profile.json, gauges/NAME.csv (NAME: a gauge's), and `sphcore plot`'s
  final.png and gauges.png.
- A file in the way, one of those names that no manifest lists (the user's own scene.json, a
  ParaView state NAME.pvd, an experiment's NAME_0000001.vtp), is never replaced or deleted: the
  run is refused naming it, --overwrite included.
- A folder whose manifest lists files holds a run. A new run into it is refused, naming
  `--resume` (where it has a checkpoint) and `--overwrite`; with overwrite the files the manifest
  lists (those that still carry a run's name and are plain files) are deleted first, and what was
  kept is said on stderr.
- A folder of an earlier sphcore (its run's files but no manifest) is refused as files in the
  way; `--resume` adopts it (its checkpoint and scene.json were checked to belong together
  first): the files under the names of that run are listed, and the run continues.
- A resumed run deletes the earlier final.npz (and the final.png drawn from it) before it writes
  its first file: the run goes on past them, and a final state older than the checkpoint would be
  drawn as if current. A resume refused before that (a damaged .pvd, no device) keeps them.
- Every write checks that the path still names the folder the run locked (st_dev, st_ino): a
  folder deleted or replaced under a running run stops it with a one-line error, and nothing is
  written into the new folder (writes go through the locked folder's descriptor).
- `.NAME.tmp-PID` files (see sphcore.output.atomic_file) whose process is gone are removed.
"""
import contextlib
import fcntl
import json
import os
import re
import stat
import sys
from pathlib import Path

import numpy as np

from sphcore.errors import FolderError
from sphcore.output import atomic_file

MANIFEST = "sphcore-run.json"
GAUGES = "gauges"  # the gauges' subfolder: gauges/NAME.csv (sphcore.gauges)
SNAPSHOT = re.compile(r".+_\d{7}(\.vtp|\.pvtp|_p\d+\.vtp)$")  # a snapshot, a parallel one, its piece
RUN_FILES = ("checkpoint.npz", "final.npz", "final.png", "scene.json", "profile.json", "gauges.png", "walls.vtp")
TEMPORARY = re.compile(r"^\..+\.tmp-(\d+)$")
# What `--overwrite` deletes (with the manifest's say-so), for `sphcore run --help`
PATTERNS = ("checkpoint.npz, final.npz, final.png, profile.json, scene.json, walls.vtp, NAME.pvd, NAME_NNNNNNN.vtp, "
            "NAME_NNNNNNN.pvtp, NAME_NNNNNNN_pR.vtp, gauges/NAME.csv, gauges.png")


def is_run_name(name):
    """Whether `name` is a file name a run (or plot, or --profile) writes: a plain name, no folder, or a gauge's
    gauges/NAME.csv (sphcore.gauges)."""
    plain = lambda n: "/" not in n and "\\" not in n and not n.startswith(".") and n != ""  # noqa: E731
    folder, _, rest = name.partition("/")
    if rest:
        return folder == GAUGES and rest.endswith(".csv") and plain(rest)
    return plain(name) and (name in RUN_FILES or name.endswith(".pvd") or bool(SNAPSHOT.match(name)))


def names_of_run(scene_name):
    """A test for the names a run of the scene named `scene_name` writes (scene.json, checkpoint.npz,
    final.npz, walls.vtp, NAME.pvd, NAME_NNNNNNN.vtp, NAME_NNNNNNN.pvtp, NAME_NNNNNNN_pR.vtp)."""
    pattern = re.compile(rf"(scene\.json|checkpoint\.npz|final\.npz|walls\.vtp|"
                         rf"{re.escape(scene_name)}(\.pvd|_\d{{7}}(\.vtp|\.pvtp|_p\d+\.vtp)))")
    return lambda name: bool(pattern.fullmatch(name))


def listed(out_dir):
    """The names out_dir's manifest lists (only those a run writes: the file is not trusted), or
    None where there is no manifest."""
    path = Path(out_dir) / MANIFEST
    try:
        data = json.loads(path.read_bytes()[:2**24])
        files = data["files"]
        if not isinstance(files, list):
            raise TypeError("files is not a list")
    except FileNotFoundError:
        return None
    except (OSError, ValueError, TypeError, KeyError) as e:
        raise FolderError(f"{path}: not a readable run manifest ({e}); move it away, or give another --out") from None
    return {f for f in files if isinstance(f, str) and is_run_name(f)}


def _listing(names, most=3):
    names = sorted(names)
    more = f" and {len(names) - most} more" if len(names) > most else ""
    return ", ".join(names[:most]) + more


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
    gauges = Path(out_dir) / GAUGES
    for path in [*Path(out_dir).iterdir(), *(gauges.iterdir() if gauges.is_dir() and not gauges.is_symlink() else ())]:
        m = TEMPORARY.match(path.name)
        if not m or int(m.group(1)) == os.getpid():
            continue
        try:
            os.kill(int(m.group(1)), 0)
        except ProcessLookupError:
            path.unlink(missing_ok=True)
        except (PermissionError, OverflowError):
            pass  # a live process of another user (or not a pid): leave its file


def missing_checkpoint(out_dir, checkpoint="checkpoint.npz"):
    """The message for a resume of `out_dir` where it has no checkpoint, with advice that works."""
    out_dir = Path(out_dir)
    path = out_dir / checkpoint
    mine = listed(out_dir) if out_dir.is_dir() else None
    if mine and any((out_dir / name).exists() for name in mine):
        return (f"{path}: no such file: {out_dir} holds a run that wrote no checkpoint, so it cannot be resumed; "
                f"start it again with `sphcore run SCENE --out {out_dir} --overwrite`")
    if out_dir.is_dir() and any(is_run_name(p.name) for p in out_dir.iterdir()):
        return (f"{path}: no such file, and no sphcore run in {out_dir} to resume (no {MANIFEST} lists its files); "
                "start a new run with `sphcore run SCENE --out` another folder")
    return (f"{path}: no such file; `sphcore run SCENE --out {out_dir}` writes one at the start "
            "and every time.checkpoint_every steps")


class RunFolder:
    """The output folder of a run, locked for as long as it is open, and its manifest.

    Every file the run writes goes through `open`, `write_bytes` or `savez`: each checks that the
    folder is still the one locked, lists the name in the manifest first (refusing a file of that
    name that no manifest lists), and writes through the folder's descriptor."""

    def __init__(self, out_dir):
        self.path = Path(out_dir)
        self.fd = lock(self.path)
        try:
            st = os.fstat(self.fd)
            self.identity = (st.st_dev, st.st_ino)
            found = listed(self.path)
        except BaseException:
            os.close(self.fd)
            raise
        self.has_manifest = found is not None
        self.names = found or set()
        self.stale = ()  # files to delete before the first write (a resume's earlier final state)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def close(self):
        if self.fd is not None:
            os.close(self.fd)
            self.fd = None

    def check(self):
        """Raise FolderError if the folder's path no longer names the folder this run locked."""
        try:
            st = os.stat(self.path)
            same = (st.st_dev, st.st_ino) == self.identity
        except OSError:
            same = False
        if not same:
            raise FolderError(f"{self.path}: the folder this run locked was deleted or replaced while it ran; "
                              "stopped, and nothing written into the folder now at that path")

    def _exists(self, name):
        try:
            os.stat(name, dir_fd=self.fd, follow_symlinks=False)
            return True
        except FileNotFoundError:
            return False

    def _save(self):
        text = json.dumps({"written_by": "sphcore", "files": sorted(self.names)}, indent=1) + "\n"
        with atomic_file(MANIFEST, dir_fd=self.fd, before_rename=self.check) as f:
            f.write(text.encode())
        self.has_manifest = True

    def claim(self, name):
        """List `name` in the manifest before it is written; refuse a file of that name the run did not write."""
        self.check()
        if name in self.names:
            return
        if self._exists(name):
            raise FolderError(f"{self.path / name}: a file no sphcore run wrote (no {MANIFEST} lists it); a run "
                              "never replaces it, --overwrite included: move it away, or give another --out")
        self.names.add(name)
        self._save()

    @contextlib.contextmanager
    def open(self, name):
        """A binary file that atomically becomes out_dir/`name` (sphcore.output.atomic_file), in this folder."""
        stale, self.stale = self.stale, ()
        for old in stale:
            self.remove(old)
        self.claim(name)
        folder, _, base = name.rpartition("/")
        if not folder:
            with atomic_file(name, dir_fd=self.fd, before_rename=self.check) as f:
                yield f
            return
        # a gauge's gauges/NAME.csv: through the subfolder's descriptor, opened from the locked folder's
        with contextlib.suppress(FileExistsError):
            os.mkdir(folder, dir_fd=self.fd)
        try:
            sub = os.open(folder, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0) | getattr(os, "O_NOFOLLOW", 0),
                          dir_fd=self.fd)
        except OSError as e:
            raise FolderError(f"{self.path / folder}: not a folder a run can write its {folder} into ({e.strerror}); "
                              "move it away, or give another --out") from None
        try:
            with atomic_file(base, dir_fd=sub, before_rename=self.check) as f:
                yield f
        finally:
            os.close(sub)

    def write_bytes(self, name, data):
        with self.open(name) as f:
            f.write(data)

    def savez(self, name, **arrays):
        """np.savez into out_dir/`name`, atomically (see sphcore.output.atomic_savez)."""
        with self.open(name) as f:
            np.savez(f, **arrays)

    def remove(self, name):
        """Delete out_dir/`name` (a file the manifest lists) and drop it from the manifest."""
        self.check()
        if name not in self.names:
            return
        with contextlib.suppress(FileNotFoundError):
            os.unlink(name, dir_fd=self.fd)
        self.names.discard(name)
        self._save()

    def _present(self):
        """Names of the entries in the folder, temporaries and the manifest left out."""
        present = {name for name in os.listdir(self.fd) if name not in (MANIFEST, GAUGES) and not TEMPORARY.match(name)}
        try:
            sub = os.open(GAUGES, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0) | getattr(os, "O_NOFOLLOW", 0),
                          dir_fd=self.fd)
        except OSError:
            return present
        try:
            return present | {f"{GAUGES}/{name}" for name in os.listdir(sub) if not TEMPORARY.match(name)}
        finally:
            os.close(sub)

    def prepare(self, scene_name, resume=False, overwrite=False):
        """Before a run of the scene named `scene_name` writes anything: refuse files in the way and,
        for a new run, a folder that holds a run (or with `overwrite` delete the files its manifest
        lists); for a resume, adopt a folder without a manifest and mark the earlier final state stale."""
        present = self._present()
        ours = names_of_run(scene_name)
        if resume and not self.has_manifest:  # a run of an earlier sphcore: its checkpoint was checked
            self.names = {name for name in present if ours(name)}
            self._save()
        in_the_way = sorted(name for name in present if ours(name) and name not in self.names)
        if in_the_way:
            raise FolderError(f"{self.path}: {_listing(in_the_way)} in the way: no sphcore run wrote "
                              f"{'them' if len(in_the_way) > 1 else 'it'} (no {MANIFEST} lists "
                              f"{'them' if len(in_the_way) > 1 else 'it'}), and a run never replaces or deletes "
                              "such files, --overwrite included: move them away, or give another --out")
        if resume:
            self.stale = ("final.npz", "final.png", "gauges.png")
            return
        held = sorted(name for name in self.names if name in present)
        if held and not overwrite:
            if "checkpoint.npz" in held:
                raise FolderError(f"{self.path} holds a run already: continue it with `sphcore run --resume "
                                  f"{self.path}`, replace it with --overwrite (deletes only the files of its "
                                  f"{MANIFEST}), or give another --out")
            raise FolderError(f"{self.path} holds a run that wrote no checkpoint, so it cannot be resumed: replace "
                              f"it with --overwrite (deletes only the files of its {MANIFEST}), or give another --out")
        deleted = []
        for name in held:
            st = os.stat(name, dir_fd=self.fd, follow_symlinks=False)
            if stat.S_ISREG(st.st_mode):  # a folder or link put under a run's name is left alone
                os.unlink(name, dir_fd=self.fd)
                deleted.append(name)
        self.names = set()
        self._save()
        if held:
            kept = sorted(self._present())
            kept_text = f"; kept {len(kept)} it did not write: {_listing(kept, 5)}" if kept else ""
            print(f"sphcore: --overwrite: deleted {len(deleted)} files of the earlier run in {self.path}{kept_text}",
                  file=sys.stderr)
