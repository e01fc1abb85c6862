"""The numba mirrors' machine code kept on disk, so that a second run of a scene does not compile.

numba's own `cache=True` cannot keep the mirrors: its index key hashes a closure's values by
pickling them (numba/core/caching.py, `Cache._index_key`), and a jitted function pickles with a
uuid drawn afresh in every process (numba/core/dispatcher.py, `Dispatcher._reduce_states`). A
stage's launch closes over its body `main`, which closes over its helpers (`kernel_w`, `cell_of`),
so its key differs in every run: it never finds its entry and adds one more each time.

`cached(launch)` gives a launch a cache whose key is made the same in every run (`fingerprint`):
the launch's bytecode and its closure's values, each jitted function among them fingerprinted in
turn by its own bytecode and closure. The specialization constants and `real` are closure values,
so two specs (DIM 2 or 3, float32 or float64, any switch a stage reads) get two entries, each in a
file of its own, and the same spec finds its entry in every run. The key also holds the call's
types (numba's signature), the CPU (numba's magic tuple), the launch's options and
NUMBA_BOUNDSCHECK. Only launches are cached: their helpers are compiled into them and come back
from disk with them.

An entry is valid only under the stamp it was written with: a hash of every .py file of the
package (a module-level helper or constant is read from the source, not from a closure). numba
adds its version. Editing sphcore or upgrading numba therefore compiles again; stale files stay
until the folder is deleted. numba does not lock an index: processes that compile the same
launch at once write the same entry, which is harmless; two processes compiling one launch for
different argument types at the same moment could cross their entries (every launch here is
called with one set of types per specialization).

Loaded entries share one process, and numba names a compiled function by its qualified name and a
counter of the process that compiled it (numba/core/bytecode.py, `FunctionIdentity`): the body of
count_cells for DIM 2, compiled in one run, and its body for DIM 3, compiled in another, can carry the
same name, and the library loaded second then calls the first one's code (seen: a 3D count_cells that
ignored z once a 2D one was loaded). So `cached` first appends its fingerprint to the qualified name of
the launch and of every jitted function in its closure: functions of different code or constants can
no longer share a name, and those that still do are the same function.

Folder: $NUMBA_CACHE_DIR/sphcore where NUMBA_CACHE_DIR is set, else $SPHCORE_CACHE_DIR/numba,
else ~/.cache/sphcore/numba (never inside the package, which may be installed read-only).

The files are untrusted input (sphcore/cache_trust.py): loading a pickle runs code, so an index or
entry is unpickled only from a folder and a file of this user's that no one else can write, and only
after its header's hashes match its key (the index: its file name; an entry: the launch's file name,
the source stamp, numba's version and the index key) and its bytes. A damaged entry is compiled again
with one CacheWarning and replaced. Where the folder cannot be trusted, no entry is read or written;
where it cannot be written, launches compile on every run: one CacheWarning, and the run goes on.
"""
import hashlib
import inspect
import itertools
import os
import pickle
from functools import lru_cache
from pathlib import Path

from numba.core import config
from numba.core.caching import CompileResultCacheImpl, FunctionCache, IndexDataCacheFile, _CacheLocator

from sphcore import cache_trust
from sphcore.paths import PACKAGE_DIR, cache_dir

LABEL = "numba cache"


def cached(launch):
    """`launch` (a numba dispatcher) with its compiled code kept on disk across runs, its jitted helpers
    (the shader body `main` and what it calls) compiled without reference counting (`without_nrt`)."""
    for cell in launch.py_func.__closure__ or ():
        without_nrt(cell.cell_contents)
    _name_by_content(launch)
    try:
        launch._cache = MirrorCache(launch)
    except RuntimeError:  # no locator: the folder cannot be written
        pass
    return launch


def numba_cache_dir():
    """Where the compiled mirrors are kept (see the module's docstring)."""
    return cache_dir("numba") if not config.CACHE_DIR else cache_dir("sphcore", config.CACHE_DIR)


@lru_cache(maxsize=None)
def source_stamp():
    """A hash of every .py file of the package."""
    digest = hashlib.sha256()
    for path in sorted(PACKAGE_DIR.rglob("*.py")):
        digest.update(str(path.relative_to(PACKAGE_DIR)).encode() + b"\0" + path.read_bytes() + b"\0")
    return digest.hexdigest()


def fingerprint(func):
    """A hash of what `func`'s compiled code depends on beyond the package's source: its bytecode
    and its closure's values, a jitted function's (or a Python function's) taken the same way."""
    digest = hashlib.sha256()
    _add_function(digest, func)
    return digest.hexdigest()


def without_nrt(func):
    """Compile jitted `func`, and each jitted function in its closure, without numba's reference counting
    (its private `_nrt` option; set before the first compile). With it every call of a function that takes
    arrays increments and decrements their counts atomically: about 30 ns a call, more than the whole
    body of a cheap stage (count_cells at 65,536 particles: 10.8 ms with it, 0.26 ms without). The
    mirrors' bodies and helpers only read and write the arrays they are given; the launches, which
    allocate a work group's shared memory, keep it."""
    if not hasattr(func, "py_func") or func.targetoptions.get("_nrt") is False:
        return
    func.targetoptions["_nrt"] = False
    for cell in func.py_func.__closure__ or ():
        without_nrt(cell.cell_contents)


def _name_by_content(func):
    """Append to the qualified name of `func` (a jitted or Python function, not yet compiled) and of each
    such function in its closure, helpers first, a hash of its code and closure (once per function)."""
    func = getattr(func, "py_func", func)
    if not inspect.isfunction(func) or getattr(func, "_sphcore_named", False):
        return
    for cell in func.__closure__ or ():
        _name_by_content(cell.cell_contents)
    func.__qualname__ += f"_{fingerprint(func)[:16]}"
    func._sphcore_named = True


def _add_function(digest, func):
    digest.update(func.__qualname__.encode() + b"\0")
    _add_code(digest, func.__code__)
    for cell in func.__closure__ or ():
        value = cell.cell_contents
        value = getattr(value, "py_func", value)  # a jitted function: its Python function
        if inspect.isfunction(value):
            _add_function(digest, value)
        else:
            digest.update(pickle.dumps(value, protocol=4))


def _add_code(digest, code):
    digest.update(pickle.dumps((code.co_code, code.co_names, code.co_varnames, code.co_freevars), protocol=4))
    for const in code.co_consts:
        if inspect.iscode(const):
            _add_code(digest, const)
        else:
            digest.update(pickle.dumps(const, protocol=4))


class MirrorLocator(_CacheLocator):
    """numba's cache locator for a launch: the folder, the stamp, and the fingerprint in the file names."""

    def __init__(self, py_func):
        self._path = str(numba_cache_dir())
        self.fingerprint = fingerprint(py_func)

    def get_cache_path(self):
        return self._path

    def get_source_stamp(self):
        return source_stamp()

    def get_disambiguator(self):
        return self.fingerprint[:24]

    def ensure_cache_path(self):
        """Before a save: the folder (created again where it went) trusted and writable, else OSError."""
        if not all(cache_trust.open_folder(self._path, Path(self._path).parent, LABEL)):
            raise OSError(f"the {LABEL} {self._path} cannot be used")

    @classmethod
    def from_function(cls, py_func, py_file):
        """The locator, or None (no cache: numba raises RuntimeError) where the folder cannot be trusted."""
        self = cls(py_func)
        readable, _ = cache_trust.open_folder(self._path, Path(self._path).parent, LABEL)
        return self if readable else None


class MirrorCacheImpl(CompileResultCacheImpl):
    _locator_classes = [MirrorLocator]


class SealedCacheFile(IndexDataCacheFile):
    """numba's index and data files, each sealed (sphcore/cache_trust.py) and unpickled only once their
    file and header pass the checks. The index's key is its file name (numba's version and the source
    stamp lead its payload, checked before unpickling: another's index is stale, not bad); an entry's key is
    the file name, numba's version, the stamp and the index key, so an index never hands over another
    launch's or another key's code. ".s1" in the names keeps numba's unsealed files (earlier versions) unread."""

    def __init__(self, cache_path, filename_base, source_stamp):
        super().__init__(cache_path, filename_base, source_stamp)
        self._base = filename_base
        self._index_path = os.path.join(cache_path, f"{filename_base}.s1.nbi")
        self._data_name_pattern = f"{filename_base}.s1.{{number:d}}.nbc"
        self._lead = f"{self._version}\0{source_stamp}\0".encode()

    def _entry_key(self, key):
        return f"{self._base}\0{self._version}\0{self._source_stamp}\0{key!r}"

    def _warn(self, path, why):
        cache_trust.warn_once(Path(path), f"ignored the cached machine code {path}: {why}; compiling it again")

    def load(self, key):
        name = self._load_index().get(key)
        if name is None:
            return None
        path = self._data_path(name)
        try:
            payload = cache_trust.read_entry(path, self._entry_key(key))
            return None if payload is None else pickle.loads(payload)
        except cache_trust.BadEntry as e:
            self._warn(path, e)
        except Exception as e:  # sealed, yet does not unpickle (e.g. a module it names went)
            self._warn(path, f"it does not load ({type(e).__name__}: {e})")
        return None

    def save(self, key, data):
        """The entry first, then the index naming it (each replaced atomically)."""
        overloads = self._load_index()
        name = overloads.get(key)
        if name is None:
            existing = set(overloads.values())
            name = next(n for n in map(self._data_name, itertools.count(1)) if n not in existing)
        cache_trust.write_entry(self._data_path(name), self._entry_key(key), self._dump(data))
        if overloads.get(key) != name:
            self._save_index({**overloads, key: name})

    def _load_index(self):
        try:
            payload = cache_trust.read_entry(self._index_path, self._base)
        except cache_trust.BadEntry as e:
            self._warn(self._index_path, e)
            return {}
        if payload is None or not payload.startswith(self._lead):
            return {}  # none, or another numba's or another source's (stale: replaced at the next save)
        try:
            return pickle.loads(payload[len(self._lead):])
        except Exception as e:
            self._warn(self._index_path, f"it does not load ({type(e).__name__}: {e})")
            return {}

    def _save_index(self, overloads):
        cache_trust.write_entry(self._index_path, self._base, self._lead + self._dump(overloads))


class MirrorCache(FunctionCache):
    """numba's cache of one launch, in sealed files (SealedCacheFile); where an entry cannot be loaded or
    saved, the launch compiles and the run goes on (a CacheWarning)."""

    _impl_class = MirrorCacheImpl

    def __init__(self, dispatcher):
        super().__init__(dispatcher.py_func)
        self._cache_file = SealedCacheFile(self._cache_path, self._impl.filename_base,
                                           self._impl.locator.get_source_stamp())
        self._options = repr(sorted(dispatcher.targetoptions.items()))

    def load_overload(self, sig, target_context):
        try:
            return super().load_overload(sig, target_context)
        except Exception as e:  # a sealed entry that numba cannot rebuild
            cache_trust.warn_once(Path(self._cache_path) / self._impl.filename_base,
                                  f"the cached machine code {self._impl.filename_base} in {self._cache_path} does "
                                  f"not load ({type(e).__name__}: {e}); compiling it again")
            return None

    def save_overload(self, sig, data):
        try:
            super().save_overload(sig, data)
        except OSError as e:
            cache_trust.warn_once(Path(self._cache_path), f"cannot write to the {LABEL} {self._cache_path} ({e}); "
                                                          f"compiled code is not kept")

    def _index_key(self, sig, codegen):
        return (sig, codegen.magic_tuple(), self._impl.locator.fingerprint, self._options, config.BOUNDSCHECK)
