"""The mirrors' compiled code on disk (sphcore/numba_cache.py): one entry per specialization, found
again by a fresh process, and never another specialization's, also where entries compiled by
different processes are loaded into one.

Run as a script, this file is the probe: it runs compute_density once for each case below (all
pairs, open domain: one stage to compile), or for those named on its command line, and prints, per
case, the density, what it needs for the reference, and the launch's cache hits and misses; with
`cells DIM...`, count_cells' cells instead."""
import json
import os
import subprocess
import sys

import numpy as np
import pytest

# name -> (kernel, precision, dimension): the first two differ only in a closure constant (KERNEL)
CASES = {"mueller": ("mueller", "float32", 2), "wendland": ("wendland_c2", "float32", 2),
         "float64": ("mueller", "float64", 2), "3d": ("mueller", "float32", 3)}


def pin_source_stamp():
    """Pin the package's source stamp in this process: an edit of sphcore while the test runs (another
    checkout's work) must not make the first process's entries stale for the second."""
    from sphcore import numba_cache
    numba_cache.source_stamp = lambda: "pinned"


def probe(names=tuple(CASES)):
    from sphcore.backends import STAGES, Stage, empty_state, make_backend
    from sphcore.scene import Scene

    out = {}
    for name in names:
        kernel, precision, dim = CASES[name]
        scene = Scene.from_dict({"physics": {"model": "graphics", "dimension": dim, "kernel": kernel, "precision": precision,
                                             "neighbour_search": "all_pairs"},
                                 "domain": {"boundary": "open", "box_min": [-1.0] * dim, "box_max": [1.0] * dim},
                                 "forces": {"gravity": [0.0] * dim},
                                 "fluid": {"blocks": [{"min": [0.0] * dim, "max": [0.06] * dim}], "spacing": 0.01}})
        x = scene.initial_positions()
        params = scene.params(len(x))
        state = empty_state(params, precision)
        state["particle_x"][:, :dim] = x
        backend = make_backend("numba", params, state, [Stage("compute_density")], scene.spec, precision=precision)
        backend.step()
        stats = STAGES["compute_density"][0](scene.spec, backend.real).stats
        out[name] = {"rho": backend.read_buffer("particle_rho").tolist(), "x": x.tolist(),
                     "h": float(params[0]["h"]), "h2": float(params[0]["h2"]),
                     "density_coef": float(params[0]["density_coef"]), "cache_path": stats.cache_path,
                     "hits": sum(stats.cache_hits.values()), "misses": sum(stats.cache_misses.values())}
    return out


def run_probe(cache_dir, names=()):
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"} | {"SPHCORE_CACHE_DIR": str(cache_dir)}
    proc = subprocess.run([sys.executable, __file__, *names], env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "CacheWarning" not in proc.stderr  # its own entries, in a folder of its own: all trusted and sound
    return json.loads(proc.stdout)


def reference_density(case, kernel):
    """rho_i = density_coef sum_j shape(r_ij), all pairs within h, in float64 (kernels.py's shapes)."""
    x = np.asarray(case["x"], np.float64)
    r2 = ((x[:, None, :] - x[None, :, :]) ** 2).sum(axis=2)
    if kernel == "mueller":
        shape = (case["h2"] - r2) ** 3
    else:
        q = np.sqrt(r2) / case["h"]
        shape = (1.0 - q) ** 4 * (1.0 + 4.0 * q)
    return case["density_coef"] * np.where(r2 < case["h2"], shape, 0.0).sum(axis=1)


def test_a_second_process_loads_each_specialization_and_only_its_own(tmp_path):
    """Process 1 compiles and saves each case; process 2, with the same folder, compiles nothing and
    computes the same bits. Each density is its own kernel's (at its own precision), so an entry
    shared by two cases (the two kernels differ only in a closure constant) fails here."""
    cold, warm = run_probe(tmp_path), run_probe(tmp_path)
    for name, (kernel, precision, _) in CASES.items():
        assert (cold[name]["hits"], cold[name]["misses"]) == (0, 1), name
        assert (warm[name]["hits"], warm[name]["misses"]) == (1, 0), name
        assert warm[name]["cache_path"] == str(tmp_path / "numba")
        assert warm[name]["rho"] == cold[name]["rho"], name
        rtol = 1e-5 if precision == "float32" else 1e-12
        for run in (cold, warm):
            np.testing.assert_allclose(run[name]["rho"], reference_density(run[name], kernel), rtol=rtol, err_msg=name)
    assert not np.allclose(cold["mueller"]["rho"], cold["wendland"]["rho"], rtol=1e-3)  # the cases do differ


def probe_cells(dims):
    """particle_cell of count_cells, the one stage compiled, on a lattice in a walled box, per dimension."""
    from sphcore.backends import Stage, empty_state, make_backend
    from sphcore.scene import Scene

    out = {}
    for dim in dims:
        scene = Scene.from_dict({"physics": {"model": "graphics", "dimension": dim}, "forces": {"gravity": [0.0] * dim},
                                 "domain": {"box_min": [0.0] * dim, "box_max": [0.1] * dim},
                                 "fluid": {"blocks": [{"min": [0.0] * dim, "max": [0.05] * dim}], "spacing": 0.01}})
        x = scene.initial_positions()
        params = scene.params(len(x))
        state = empty_state(params)
        state["particle_x"][:, :dim] = x
        backend = make_backend("numba", params, state, [Stage("count_cells")], scene.spec)
        backend.step()
        out[str(dim)] = {"cell": backend.read_buffer("particle_cell").tolist(), "x": x.tolist(),
                         "inv_cell": float(params[0]["inv_cell"]), "grid_dim": params[0]["grid_dim"].tolist()}
    return out


def test_entries_compiled_apart_load_into_one_process(tmp_path):
    """count_cells for 2D and for 3D, each compiled by a process of its own (so numba numbers their
    functions alike), then both loaded by one process: each finds its own cells (3D: z counts). With
    numba's names alone, the one loaded second ran the first one's code."""
    apart = {**run_probe(tmp_path, ["cells", "2"]), **run_probe(tmp_path, ["cells", "3"])}
    together = run_probe(tmp_path, ["cells", "2", "3"])
    for dim in ("2", "3"):
        case = together[dim]
        c = np.floor(np.asarray(case["x"], np.float32) * np.float32(case["inv_cell"])).astype(np.int64)
        d = case["grid_dim"]
        expected = c[:, 0] + d[0] * (c[:, 1] + (d[1] * c[:, 2] if dim == "3" else 0))
        assert case["cell"] == expected.tolist() == apart[dim]["cell"], dim


def test_cache_folder(monkeypatch, tmp_path):
    """NUMBA_CACHE_DIR if set, else SPHCORE_CACHE_DIR, else ~/.cache/sphcore; never the package."""
    from numba.core import config

    from sphcore.numba_cache import numba_cache_dir
    from sphcore.paths import PACKAGE_DIR

    monkeypatch.setattr(config, "CACHE_DIR", "")
    monkeypatch.delenv("SPHCORE_CACHE_DIR", raising=False)
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert numba_cache_dir() == tmp_path / "home" / ".cache" / "sphcore" / "numba"
    monkeypatch.setenv("SPHCORE_CACHE_DIR", str(tmp_path / "sphcore"))
    assert numba_cache_dir() == tmp_path / "sphcore" / "numba"
    monkeypatch.setattr(config, "CACHE_DIR", str(tmp_path / "numba"))
    assert numba_cache_dir() == tmp_path / "numba" / "sphcore"
    assert PACKAGE_DIR not in numba_cache_dir().parents


@pytest.mark.parametrize("other", [{"KERNEL": 1}, {"DIM": 2}, {"TAIT": 1}])
def test_fingerprint_follows_the_closure_constants(other):
    """Equal specs give equal fingerprints (built twice, bypassing the factory's memo); a switch the
    stage reads changes it, so its entry gets a file and key of its own."""
    from sphcore.numba_cache import fingerprint
    from sphcore.params import Spec
    from sphcore.sph.compute_density import compute_density

    def of(spec, real=np.float32):
        return fingerprint(compute_density.__wrapped__(spec, real).py_func)

    assert of(Spec()) == of(Spec())
    assert of(Spec(**other)) != of(Spec())
    assert of(Spec(), np.float64) != of(Spec())


if __name__ == "__main__":
    pin_source_stamp()
    if sys.argv[1:2] == ["cells"]:
        print(json.dumps(probe_cells([int(d) for d in sys.argv[2:]])))
    else:
        print(json.dumps(probe(sys.argv[1:] or tuple(CASES))))
