"""Particle shifting (issue 31, physics.shifting = "lind": Lind et al. 2012, shaders/sph/shifting.glsl): its sums
against a float64 all-pairs reference, numba and lavapipe bit for bit with it on (the sums too, step by step in a
dam break), a disordered block made more uniform, a free surface kept, and the keys."""
import numpy as np
import pytest
import reference
import test_switch_matrix as matrix
from conftest import BACKENDS, particles, scene_changed, scene_state, vulkan_or_skip

from sphcore.backends import make_backend
from sphcore.scene import SceneError

# a closed box full of water, no gravity (the block test), and a dam-break column (the free-surface test)
BOX = {"physics": {"model": "engineering", "density": "summation", "density_diffusion": "none", "gravity": False,
                   "shifting": "lind"},
       "domain": {"box_min": [0.0, 0.0], "box_max": [0.2, 0.2]},
       "fluid": {"spacing": 0.01, "blocks": [{"min": [0.0, 0.0], "max": [0.2, 0.2]}]},
       "forces": {"gravity": [0.0, 0.0]}, "time": {"dt": 1e-4}}
COLUMN = {"physics": {"model": "engineering", "shifting": "lind"},
          "domain": {"box_min": [0.0, 0.0], "box_max": [0.6, 0.3]},
          "fluid": {"spacing": 0.01, "blocks": [{"min": [0.0, 0.0], "max": [0.1, 0.2]}]},
          "forces": {"gravity": [0.0, -9.81]}, "time": {"dt": 2e-4}}


def nearest(x):
    """Each particle's distance to its nearest other particle."""
    d = np.sqrt(((x[:, None, :] - x[None, :, :]) ** 2).sum(axis=-1))
    np.fill_diagonal(d, np.inf)
    return d.min(axis=1)


def disorder(x):
    """The spread of the nearest-neighbour distances over their mean: 0 on a lattice."""
    d = nearest(x)
    return d.std() / d.mean()


@pytest.mark.parametrize("dim", [2, 3])
def test_sums_match_the_all_pairs_reference(dim):
    """compute_forces' (grad C_i, div r_i) (scratch_v) on a jittered lattice beside the walls, Mueller's kernels,
    against tests/reference.py in float64: float32 sums of a few dozen terms, within 1e-4 of their scale."""
    spacing = 0.02
    scene = scene_changed({"physics": {"model": "graphics", "dimension": dim, "shifting": "lind"},
                           "domain": {"box_min": [0.0] * dim, "box_max": [0.2] * dim},
                           "fluid": {"spacing": spacing, "blocks": [{"min": [0.0] * dim, "max": [0.12] * dim}]},
                           "forces": {"gravity": [0.0, -9.81, 0.0][:dim]}})
    state, params, stages, spec = scene_state(scene, jitter=0.3, seed=4)
    be = make_backend("numba", params, state, stages, spec)
    for stage in stages:  # the sort, the density, the forces
        be.run_stage(stage)
        if stage.name == "compute_forces":
            break
    out = be.read()
    n = len(out["particle_rho"])
    x = out["particle_x"][:, :dim].astype(np.float64)
    grad_c, div_r = reference.shifting_sums(x, out["particle_rho"].astype(np.float64), scene.mass, scene.h, spacing,
                                            np.array(scene["domain.box_min"]), np.array(scene["domain.box_max"]))
    sums = out["scratch_v"][:n].astype(np.float64)
    assert np.abs(sums[:, :dim] - grad_c).max() < 1e-4 * np.abs(grad_c).max()
    assert np.abs(sums[:, 3] - div_r).max() < 1e-4 * np.abs(div_r).max()
    assert 0.8 * dim < np.median(div_r) < 1.2 * dim  # inside the fluid div r is about dim
    be.close()


# numba and lavapipe from the same scenes with shifting on: 2D and 3D, summation and continuity, an obstacle,
# reused lists, Verlet (test_switch_matrix's tiny scenes; its sample crosses the switch with every other)
AGREE = [{"physics.dimension": 2},
         {"physics.dimension": 2, "physics.density": "continuity", "physics.density_diffusion": "fourtakas",
          "domain.obstacles": "box"},
         {"physics.dimension": 3, "physics.list_skin": 0.2},
         {"physics.dimension": 3, "physics.density": "continuity", "physics.density_diffusion": "fourtakas",
          "time.integrator": "verlet"}]


@pytest.mark.vulkan
@pytest.mark.parametrize("case", AGREE, ids=lambda c: "-".join(str(v) for v in c.values()))
def test_backends_agree_bit_for_bit(case):
    vulkan_or_skip()
    combo = dict(matrix.ISSUE_30, **{"physics.pressure_solver": "state_equation", "physics.shifting": "lind"}, **case)
    out, scene = matrix.run_both(combo, steps=20)
    assert scene.spec.SHIFTING == 1
    assert matrix.failures(matrix.differences(out, scene), rtol=0.0) == []
    a, b = out["numba"][0], out["vulkan"][0]
    assert np.abs(a["scratch_v"][:, 3]).max() > 1.0  # the sums were written (div r about dim)
    assert np.array_equal(a["scratch_v"], b["scratch_v"])  # and are the same (both sorts agree: the same order)


# A 10 x 10 dam break with the engineering preset (Wendland C2, continuity density, Verlet, adaptive dt), every
# step compared. With shifting_lind's `c` unmarked (shifting.glsl: `precise`) lavapipe's sums parted from numba's
# at step 2 in grad C_i's last bit, in float32 and float64, and the positions only later (1 ulp by step 150 in
# float32): the test above, which compared the positions after 20 steps and not the sums, passed.
DAM = {"physics": {"model": "engineering", "shifting": "lind"},
       "domain": {"box_min": [0.2, 0.2], "box_max": [0.8, 1.0]},
       "fluid": {"spacing": 0.04, "blocks": [{"min": [0.2, 0.2], "max": [0.6, 0.6]}]}}
DAM_STEPS = 40
DAM_BUFFERS = ("particle_x", "particle_v", "particle_rho", "particle_p", "scratch_v", "time_state")


@pytest.mark.vulkan
@pytest.mark.parametrize("precision", ["float32", "float64"])
def test_a_dam_break_agrees_bit_for_bit_step_by_step(open_backend, precision):
    """Both backends from the same state, every buffer that carries the physics (and the sums, scratch_v)
    compared bitwise after each of DAM_STEPS steps."""
    scene = scene_changed(DAM, **{"physics.precision": precision})
    state, params, stages, spec = scene_state(scene)
    be = {name: open_backend(name, params, state, stages, spec, precision=precision) for name in BACKENDS}
    for step in range(1, DAM_STEPS + 1):
        out = {}
        for name, backend in be.items():
            backend.step(1)
            out[name] = backend.read(DAM_BUFFERS)
        for buffer in DAM_BUFFERS:
            assert np.array_equal(out["numba"][buffer], out["vulkan"][buffer]), f"step {step}: {buffer} differs"
    assert np.abs(out["numba"]["scratch_v"][:, :2]).max() > 1.0  # shifting's sums were written
    assert np.abs(out["numba"]["particle_v"]).max() > 0.5  # and the column moves (measured 1.5 m/s at t = 0.077 s)


def run_numba(config, steps, chunks=1, jitter=0.0, **changes):
    """The particles (in id order) of `config` with `changes`, at the start and after each of `chunks` runs of
    `steps` steps on numba."""
    scene = scene_changed(config, **changes)
    state, params, stages, spec = scene_state(scene, jitter=jitter, seed=3)
    be = make_backend("numba", params, state, stages, spec)
    out = [particles(be, scene.dim)]
    for _ in range(chunks):
        be.step(steps)
        out.append(particles(be, scene.dim))
    be.close()
    return out


def test_a_disordered_block_becomes_more_uniform():
    """A box full of water jittered by 0.3 dx, no gravity: the pressure noise sets it moving; with shifting the
    spread of nearest-neighbour distances falls to under 0.6 of its start (measured: 0.178 to 0.087 in 800 steps),
    without it stays (0.189)."""
    shifted = run_numba(BOX, 400, chunks=2, jitter=0.3)
    plain = run_numba(BOX, 400, chunks=2, jitter=0.3, **{"physics.shifting": "none"})
    start = disorder(shifted[0]["particle_x"].astype(np.float64))
    assert start == disorder(plain[0]["particle_x"].astype(np.float64))
    assert disorder(shifted[-1]["particle_x"].astype(np.float64)) < 0.6 * start
    assert disorder(plain[-1]["particle_x"].astype(np.float64)) > 0.9 * start


def test_the_free_surface_is_kept():
    """A dam-break column, 0.15 s: with shifting no particle leaves the fluid (each keeps a neighbour within
    1.5 dx: the free-surface threshold stops the shift that would push surface particles out), the front and the
    top stay within dx / 2 of the run without it, and the interior is more uniform."""
    dx = COLUMN["fluid"]["spacing"]
    shifted = run_numba(COLUMN, 750)[-1]["particle_x"].astype(np.float64)
    plain = run_numba(COLUMN, 750, **{"physics.shifting": "none"})[-1]["particle_x"].astype(np.float64)
    assert nearest(shifted).max() < 1.5 * dx
    assert abs(shifted[:, 0].max() - plain[:, 0].max()) < dx / 2
    assert abs(shifted[:, 1].max() - plain[:, 1].max()) < dx / 2
    assert disorder(shifted) < disorder(plain)


def test_keys():
    """physics.shifting takes its names, fluid.shifting its range; DFSPH is refused naming both keys."""
    scene = scene_changed(COLUMN)
    assert scene.spec.SHIFTING == 1 and scene.params(10)[0]["shifting_coef"] > 0
    assert scene_changed(COLUMN, **{"physics.shifting": "none"}).spec.SHIFTING == 0
    with pytest.raises(SceneError, match="physics.shifting"):
        scene_changed(COLUMN, **{"physics.shifting": "fickian"})
    with pytest.raises(SceneError, match="fluid.shifting"):
        scene_changed(COLUMN, **{"fluid.shifting": -1.0})
    with pytest.raises(SceneError, match="physics.shifting.*physics.pressure_solver"):
        scene_changed(COLUMN, **{"physics.pressure_solver": "dfsph", "physics.density": "summation",
                                 "physics.density_diffusion": "none", "time.integrator": "symplectic_euler"})
