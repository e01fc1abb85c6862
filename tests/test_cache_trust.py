"""The compiled-code caches as untrusted input (issue 30, section 2; sphcore/cache_trust.py): a planted
pickle or SPIR-V in a folder or file that others can write (mode 1777, another uid) is never read; a
damaged entry (garbage, truncated, altered) is compiled again with one warning, never run, and replaced;
both backends run with no writable cache.

The numba cases run a tiny launch given the mirrors' cache (`cached`) in a fresh process each: this file
run as a script is that probe. The SPIR-V cases call compile_glsl, and a short Vulkan run checks the
physics after every cached shader was damaged: a block falls under gravity."""
import hashlib
import json
import os
import pickle
import shutil
import subprocess
import sys
import warnings

import numpy as np
import pytest

from conftest import VALIDATION, skip_unless_compiler, vulkan_or_skip
from sphcore import cache_trust
from sphcore.cache_trust import CacheWarning

OTHER_UID = 65534  # nobody
EXPECTED_Y = 2.0 * 3.0 + 1.0  # the probe's launch(2.0)


def probe():
    """Run the tiny cached launch once; print its result and cache hits and misses (JSON). The source
    stamp is pinned: an edit of the package between two probes must not make the entry stale here."""
    import numba

    from sphcore import numba_cache
    from sphcore.numba_cache import cached

    numba_cache.source_stamp = lambda: "pinned"
    if os.environ.get("TEST_CACHE_READ_ONLY"):
        numba_cache.cache_trust.tempfile = read_only_tempfile()

    def make(scale):
        @numba.njit
        def launch(x):
            return x * scale + 1.0
        return launch

    launch = cached(make(3.0))
    y = launch(2.0)
    stats = launch.stats
    print(json.dumps({"y": y, "hits": sum(stats.cache_hits.values()), "misses": sum(stats.cache_misses.values())}))


def read_only_tempfile():
    """A stand-in for sphcore.cache_trust's `tempfile` that cannot create a file anywhere, as in a read-only
    folder for any user but root (these tests run as root in CI)."""
    from types import SimpleNamespace

    def refuse(*args, dir=None, **kwargs):
        raise PermissionError(13, "Permission denied", str(dir))

    return SimpleNamespace(TemporaryFile=refuse, mkstemp=refuse)


def run_probe(cache_root, read_only=False):
    """(result, the CacheWarning lines on stderr) of the probe in a fresh process with SPHCORE_CACHE_DIR=cache_root
    (`read_only`: its folders cannot be written)."""
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"} | {"SPHCORE_CACHE_DIR": str(cache_root)}
    if read_only:
        env["TEST_CACHE_READ_ONLY"] = "1"
    proc = subprocess.run([sys.executable, __file__], env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout), [line for line in proc.stderr.splitlines() if "CacheWarning" in line]


@pytest.fixture(scope="module")
def filled(tmp_path_factory):
    """A cache root whose numba folder holds the probe's compiled launch (index and entry)."""
    root = tmp_path_factory.mktemp("filled")
    result, warned = run_probe(root)
    assert (result["y"], result["misses"], warned) == (EXPECTED_Y, 1, [])
    return root


def copy_of(filled, tmp_path):
    """A fresh copy of the filled cache root (modes kept): (root, index file, entry file)."""
    root = tmp_path / "cache"
    shutil.copytree(filled, root)
    folder = root / "numba"
    (index,), (entry,) = folder.glob("*.nbi"), folder.glob("*.nbc")
    return root, index, entry


class Planted:
    """A pickle that, when loaded, creates the file `marker` (what an attacker's would do instead)."""

    def __init__(self, marker):
        self.marker = marker

    def __reduce__(self):
        return os.system, (f"touch {self.marker}",)


def forge(path, payload):
    """Put `payload` in the entry at `path` under the header an attacker can compute: the entry's own key
    digest, the payload's hash."""
    blob = path.read_bytes()
    key_digest = blob[len(cache_trust.MAGIC):len(cache_trust.MAGIC) + 32]
    path.write_bytes(cache_trust.MAGIC + key_digest + hashlib.sha256(payload).digest() + payload)


def test_a_second_process_loads_the_entry(filled, tmp_path):
    """The sealed entry is found again: the checks below do not just disable the cache."""
    root, _, _ = copy_of(filled, tmp_path)
    result, warned = run_probe(root)
    assert (result["y"], result["hits"], result["misses"], warned) == (EXPECTED_Y, 1, 0, [])


def test_forged_pickle_runs_in_a_trusted_folder(filled, tmp_path):
    """The control for the next test: a pickle forged with a valid header runs where the folder and file are
    the user's own (the hashes find damage, not malice): only the ownership checks keep it out."""
    root, _, entry = copy_of(filled, tmp_path)
    marker = tmp_path / "planted_ran"
    forge(entry, pickle.dumps(Planted(marker)))
    run_probe(root)
    assert marker.exists()


@pytest.mark.parametrize("where", ["folder 1777", "folder of another uid", "entry of another uid", "entry a symlink"])
def test_planted_pickle_never_runs(filled, tmp_path, where):
    """The forged pickle of the control above is not even opened where others could have written the folder
    or the file: one warning naming the folder or file, the launch compiled; nothing written into a folder
    of another's, an entry of another's replaced by the user's own."""
    root, index, entry = copy_of(filled, tmp_path)
    marker = tmp_path / "planted_ran"
    forge(entry, pickle.dumps(Planted(marker)))
    folder = entry.parent
    if where == "folder 1777":
        folder.chmod(0o1777)
    elif where == "folder of another uid":
        os.chown(folder, OTHER_UID, OTHER_UID)
    elif where == "entry of another uid":
        os.chown(entry, OTHER_UID, OTHER_UID)
    else:
        target = tmp_path / "elsewhere.nbc"
        entry.rename(target)
        entry.symlink_to(target)
    before = sorted(p.name for p in folder.iterdir())
    result, warned = run_probe(root)
    assert not marker.exists()
    assert (result["y"], result["hits"], result["misses"]) == (EXPECTED_Y, 0, 1)
    assert len(warned) == 1
    if where.startswith("folder"):
        why = "writable by group or others (mode 1777)" if "1777" in where else f"owned by uid {OTHER_UID}"
        assert f"not using the numba cache {folder}: it is {why}" in warned[0]
        assert sorted(p.name for p in folder.iterdir()) == before  # nothing written into it either
    else:
        why = f"owned by uid {OTHER_UID}" if "uid" in where else "a symbolic link"
        assert f"ignored the cached machine code {entry}: it is {why}" in warned[0]
        assert "compiling it again" in warned[0]
        assert not entry.is_symlink() and entry.stat().st_uid == os.geteuid()  # replaced by the user's own
        assert entry.stat().st_mode & 0o077 == 0


def assert_sealed_like(path, original):
    """`path` holds a sound entry (its payload matches its hash) for the same key as bytes `original`."""
    blob, m = path.read_bytes(), len(cache_trust.MAGIC)
    assert blob[:m + 32] == original[:m + 32]
    assert blob[m + 32:cache_trust.HEADER_SIZE] == hashlib.sha256(blob[cache_trust.HEADER_SIZE:]).digest()


@pytest.mark.parametrize("file, damage", [("entry", "garbage"), ("entry", "truncated"), ("index", "truncated")])
def test_damaged_numba_file_is_compiled_again_and_replaced(filled, tmp_path, file, damage):
    """Garbage or a truncated file in place of the index or the entry (these ended in UnpicklingError and
    ValueError tracebacks): one warning naming the file, the launch compiled and right, the file replaced."""
    root, index, entry = copy_of(filled, tmp_path)
    path = {"entry": entry, "index": index}[file]
    original = path.read_bytes()
    path.write_bytes(np.random.default_rng(0).bytes(len(original)) if damage == "garbage"
                     else original[:len(original) // 2])
    result, warned = run_probe(root)
    assert (result["y"], result["hits"], result["misses"]) == (EXPECTED_Y, 0, 1)
    assert len(warned) == 1 and f"ignored the cached machine code {path}: it is" in warned[0]
    assert "compiling it again" in warned[0]
    assert_sealed_like(path, original)


def test_numba_runs_with_no_writable_cache(tmp_path):
    """SPHCORE_CACHE_DIR names a file: one warning naming the folder, the launch compiled and right."""
    root = tmp_path / "cache"
    root.write_text("not a folder")
    result, warned = run_probe(root)
    assert (result["y"], result["misses"]) == (EXPECTED_Y, 1)
    assert len(warned) == 1 and f"cannot create the numba cache {root / 'numba'}" in warned[0]


def test_numba_reads_a_read_only_cache_and_writes_nothing(filled, tmp_path):
    """A read-only folder of the user's: its sound entry is loaded; where there is none, the launch
    compiles, with one warning that the code is not kept, and nothing is written."""
    root, _, _ = copy_of(filled, tmp_path)
    result, warned = run_probe(root, read_only=True)
    assert (result["y"], result["hits"], result["misses"]) == (EXPECTED_Y, 1, 0)
    assert len(warned) == 1 and f"cannot write to the numba cache {root / 'numba'}" in warned[0]
    for path in (root / "numba").iterdir():
        path.unlink()
    result, warned = run_probe(root, read_only=True)
    assert (result["y"], result["hits"], result["misses"]) == (EXPECTED_Y, 0, 1)
    assert len(warned) == 1 and f"cannot write to the numba cache {root / 'numba'}" in warned[0]
    assert list((root / "numba").iterdir()) == []


# --- SPIR-V -----------------------------------------------------------------------------------------------

def shader(name):
    from sphcore.paths import SHADER_DIR
    return SHADER_DIR / "sph" / f"{name}.comp"


def compiled(monkeypatch, root, name):
    """(SPIR-V of shader `name` with SPHCORE_CACHE_DIR=root, the CacheWarnings it gave)."""
    from sphcore.vk_runner import compile_glsl
    monkeypatch.setenv("SPHCORE_CACHE_DIR", str(root))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        code = compile_glsl(shader(name))
    return code, [str(w.message) for w in caught if issubclass(w.category, CacheWarning)]


@pytest.mark.parametrize("where", ["folder 1777", "folder of another uid", "entry mode 666", "entry a symlink"])
def test_planted_spirv_is_never_used(monkeypatch, tmp_path, where):
    """Another shader's SPIR-V, sealed as compute_density's entry (as an attacker can): used where the folder
    and file are the user's own (the control), never where others could have written them."""
    skip_unless_compiler()
    genuine, warned = compiled(monkeypatch, tmp_path / "cache", "compute_density")
    assert warned == []
    (entry,) = (tmp_path / "cache" / "spirv").glob("compute_density-*.spv")
    other, _ = compiled(monkeypatch, tmp_path / "other", "integrate")
    forge(entry, other)
    assert compiled(monkeypatch, tmp_path / "cache", "compute_density")[0] == other  # the control

    folder = entry.parent
    if where == "folder 1777":
        folder.chmod(0o1777)
    elif where == "folder of another uid":
        os.chown(folder, OTHER_UID, OTHER_UID)
    elif where == "entry mode 666":
        entry.chmod(0o666)
    else:
        target = tmp_path / "elsewhere.spv"
        entry.rename(target)
        entry.symlink_to(target)
    code, warned = compiled(monkeypatch, tmp_path / "cache", "compute_density")
    assert code == genuine
    assert len(warned) == 1
    if where.startswith("folder"):
        assert f"not using the shader cache {folder}: it is" in warned[0]
        assert entry.read_bytes()[cache_trust.HEADER_SIZE:] == other  # left as it was: nothing written into it
    else:
        assert f"ignored the cached SPIR-V {entry}: it is" in warned[0]
        assert not entry.is_symlink() and entry.read_bytes()[cache_trust.HEADER_SIZE:] == genuine  # replaced


DAMAGES = {"flipped byte": lambda b: b[:500] + bytes([b[500] ^ 0x40]) + b[501:], "truncated": lambda b: b[:1000],
           "garbage": lambda b: np.random.default_rng(0).bytes(len(b)), "empty": lambda b: b"",
           "unsealed SPIR-V": lambda b: b[cache_trust.HEADER_SIZE:]}


@pytest.mark.parametrize("damage", list(DAMAGES))
def test_damaged_spirv_is_compiled_again_and_replaced(monkeypatch, tmp_path, damage):
    skip_unless_compiler()
    genuine, _ = compiled(monkeypatch, tmp_path / "cache", "compute_density")
    (entry,) = (tmp_path / "cache" / "spirv").glob("compute_density-*.spv")
    entry.write_bytes(DAMAGES[damage](entry.read_bytes()))
    code, warned = compiled(monkeypatch, tmp_path / "cache", "compute_density")
    assert code == genuine
    assert len(warned) == 1 and f"ignored the cached SPIR-V {entry}: it is" in warned[0]
    assert compiled(monkeypatch, tmp_path / "cache", "compute_density") == (genuine, [])  # replaced


def test_spirv_read_only_cache(monkeypatch, tmp_path):
    """A read-only folder of the user's: its sound entry is used; a shader not in it compiles, with one
    warning that the code is not kept, and nothing is written."""
    skip_unless_compiler()
    genuine, _ = compiled(monkeypatch, tmp_path / "cache", "compute_density")
    folder = tmp_path / "cache" / "spirv"
    before = sorted(folder.iterdir())
    monkeypatch.setattr(cache_trust, "tempfile", read_only_tempfile())
    code, warned = compiled(monkeypatch, tmp_path / "cache", "compute_density")
    assert code == genuine and len(warned) == 1 and f"cannot write to the shader cache {folder}" in warned[0]
    fresh, warned = compiled(monkeypatch, tmp_path / "cache", "integrate")
    assert fresh[:4] == (0x07230203).to_bytes(4, "little") and warned == []  # (warned once per folder)
    assert sorted(folder.iterdir()) == before


def test_check_spirv():
    from sphcore.vk_runner.compiler import check_spirv
    header = (0x07230203).to_bytes(4, "little") + bytes(16)
    check_spirv(header)
    for bad in (header[:16], header + b"\0", b"\7\x23\2\3" + bytes(16), bytes(20)):
        with pytest.raises(cache_trust.BadEntry, match="not SPIR-V"):
            check_spirv(bad)


# a 4 x 4 block high in a 2D tank, 20 steps: it falls freely (no wall within reach)
FALLING = {"name": "falling", "physics": {"model": "graphics", "dimension": 2},
           "domain": {"box_min": [0.0, 0.0], "box_max": [0.4, 0.4]},
           "fluid": {"blocks": [{"min": [0.18, 0.3], "max": [0.22, 0.34]}], "spacing": 0.01},
           "time": {"dt": 1e-3}}
STEPS = 20


def fall_on_vulkan(monkeypatch, root):
    """(the block's fall of its centre of mass [m] on Vulkan with SPHCORE_CACHE_DIR=root, CacheWarnings)."""
    from sphcore.scene import Scene
    from sphcore.simulation import Simulation

    monkeypatch.setenv("SPHCORE_CACHE_DIR", str(root))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with Simulation(Scene.from_dict(FALLING), "vulkan", validation=VALIDATION) as sim:
            y0 = sim.read()["particle_x"][:, 1].mean()
            sim.advance(STEPS)
            y = sim.read()["particle_x"][:, 1].mean()
    return float(y0 - y), [str(w.message) for w in caught if issubclass(w.category, CacheWarning)]


def free_fall():
    """g t^2 / 2 after STEPS steps, and symplectic Euler's O(dt) departure from it: g t dt."""
    t = STEPS * FALLING["time"]["dt"]
    return 9.81 * t * t / 2, 9.81 * t * FALLING["time"]["dt"]


@pytest.mark.vulkan
def test_damaged_spirv_never_runs_on_vulkan(monkeypatch, tmp_path):
    """Every cached shader damaged (truncated to 1,000 bytes, or one byte flipped): the run warns once per
    shader, recompiles, and the block falls as in free fall (a damaged shader used to leave it frozen)."""
    vulkan_or_skip()
    fall, tolerance = free_fall()
    dropped, warned = fall_on_vulkan(monkeypatch, tmp_path / "cache")
    assert dropped == pytest.approx(fall, abs=tolerance) and warned == []
    entries = sorted((tmp_path / "cache" / "spirv").glob("*.spv"))
    assert len(entries) > 3
    for k, entry in enumerate(entries):
        entry.write_bytes(DAMAGES["truncated" if k % 2 else "flipped byte"](entry.read_bytes()))
    dropped, warned = fall_on_vulkan(monkeypatch, tmp_path / "cache")
    assert dropped == pytest.approx(fall, abs=tolerance)
    assert sorted(w.split("ignored the cached SPIR-V ")[1].split(":")[0] for w in warned) == list(map(str, entries))


@pytest.mark.vulkan
def test_vulkan_runs_with_no_writable_cache(monkeypatch, tmp_path):
    """SPHCORE_CACHE_DIR a file: one warning naming the shader cache, the run compiles in memory and falls."""
    vulkan_or_skip()
    root = tmp_path / "cache"
    root.write_text("not a folder")
    fall, tolerance = free_fall()
    dropped, warned = fall_on_vulkan(monkeypatch, root)
    assert dropped == pytest.approx(fall, abs=tolerance)
    assert len(warned) == 1 and f"cannot create the shader cache {root / 'spirv'}" in warned[0]


if __name__ == "__main__":
    probe()
