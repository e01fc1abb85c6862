"""Compiled code kept on disk, read as untrusted input (the numba mirrors' machine code in
sphcore/numba_cache.py, SPIR-V in sphcore/vk_runner/compiler.py).

As Python does with __pycache__, an entry is read only from a folder owned by this user and not
writable by group or others, and only where the entry itself is a regular file (not a symbolic link)
owned by this user and not writable by group or others: anyone who can write the folder could
plant machine code, or a pickle that runs when loaded. Folders are created with mode 0o700.

Each entry is sealed: a header holds a SHA-256 of its key (what it was compiled from) and of its
payload, checked before the payload is unpickled or handed to the driver, so a truncated, damaged
or misplaced entry is compiled again (with a one-line CacheWarning) and replaced, never run. The
hashes find damage, not malice: a forger who can write the folder can also hash; the ownership
checks keep the forger out.

A cache folder that cannot be trusted, created or written costs its compiled code, never the run:
one warning, and the code is compiled without it.
"""
import errno
import hashlib
import os
import stat
import tempfile
import warnings
from pathlib import Path

from sphcore.errors import BadEntry, CacheWarning

MAGIC = b"sphcore cache 1\n"
HEADER_SIZE = len(MAGIC) + 2 * 32  # MAGIC, SHA-256 of the key, SHA-256 of the payload


_warned = set()


def warn_once(about, message):
    """Warn `message` (one line) the first time this process warns about `about` (a folder or file)."""
    if about not in _warned:
        _warned.add(about)
        warnings.warn(CacheWarning(f"sphcore: {message}"), stacklevel=3)


def _reason(error):
    """An OSError in words: what and where."""
    return f"{error.strerror}: {error.filename}" if error.strerror and error.filename else str(error)


def _problem(st, what):
    """Why a file or folder with stat `st` is not to be trusted, or None."""
    if st.st_uid != os.geteuid():
        return f"{what} is owned by uid {st.st_uid}, not by this user (uid {os.geteuid()})"
    if st.st_mode & 0o022:
        return f"{what} is writable by group or others (mode {stat.S_IMODE(st.st_mode):o})"
    return None


def open_folder(folder, root, label):
    """(readable, writable) of cache folder `folder` (a Path inside or equal to `root`), created (with mode
    0o700, its missing parents down from `root` too) where missing. Readable only where `root` and
    each folder below it down to `folder` is owned by this user and not writable by group or others;
    where not, or where it cannot be created or written, warns once, naming the folder and why."""
    folder, root = Path(folder), Path(root)
    chain = [root, *reversed([p for p in folder.parents if root in p.parents]), folder] if folder != root else [root]
    try:
        for path in [*reversed(root.parents), *chain]:
            if not path.is_dir():
                try:
                    os.mkdir(path, 0o700)
                except FileExistsError:  # created meanwhile by another process, or a file
                    pass
            if path not in chain:  # above the root (created here where missing): the user's own choice
                continue
            st = os.stat(path)
            if not stat.S_ISDIR(st.st_mode):
                raise NotADirectoryError(errno.ENOTDIR, "not a folder", str(path))
            why = _problem(st, "it" if path == folder else f"its parent {path}")
            if why:
                warn_once(folder, f"not using the {label} {folder}: {why}; compiling without it (give "
                                  f"the cache a folder only you can write)")
                return False, False
    except OSError as e:
        warn_once(folder, f"cannot create the {label} {folder} ({_reason(e)}); compiling without it")
        return False, False
    try:
        tempfile.TemporaryFile(dir=folder).close()
    except OSError as e:
        warn_once(folder, f"cannot write to the {label} {folder} ({_reason(e)}); compiled code is not kept")
        return True, False
    return True, True


def seal(key, payload):
    """The bytes of an entry: the header for `key` (bytes or str) and `payload`, then the payload."""
    key = key.encode() if isinstance(key, str) else key
    return MAGIC + hashlib.sha256(key).digest() + hashlib.sha256(payload).digest() + payload


def unseal(blob, key):
    """The payload of entry bytes `blob` sealed for `key`; raises BadEntry where it is not that."""
    key = key.encode() if isinstance(key, str) else key
    if len(blob) < HEADER_SIZE or not blob.startswith(MAGIC):
        raise BadEntry(f"it is not a sphcore cache entry ({len(blob)} bytes without the header)")
    payload = blob[HEADER_SIZE:]
    if blob[len(MAGIC):len(MAGIC) + 32] != hashlib.sha256(key).digest():
        raise BadEntry("it was compiled from something else (its key differs)")
    if blob[len(MAGIC) + 32:HEADER_SIZE] != hashlib.sha256(payload).digest():
        raise BadEntry(f"it is damaged: its {len(payload)} bytes do not match their hash (truncated or altered)")
    return payload


def read_entry(path, key):
    """The payload of the entry at `path` sealed for `key`, or None where there is no file; raises BadEntry
    where it is a symbolic link, not a regular file, not this user's, writable by others, or not sealed
    for `key`."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK)
    except FileNotFoundError:
        return None
    except OSError as e:
        raise BadEntry("it is a symbolic link" if e.errno == errno.ELOOP else f"it cannot be read ({e.strerror})")
    with os.fdopen(fd, "rb") as f:
        st = os.fstat(f.fileno())
        if not stat.S_ISREG(st.st_mode):
            raise BadEntry("it is not a regular file")
        why = _problem(st, "it")
        if why:
            raise BadEntry(why)
        blob = f.read()
    return unseal(blob, key)


def write_entry(path, key, payload):
    """Write the entry for `key` at `path` atomically (a file of mode 0o600 renamed over it); raises OSError."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name + ".", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(seal(key, payload))
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
