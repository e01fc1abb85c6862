"""The neighbour grid (HistoPyramid counting sort) against an all-pairs reference, and Vulkan
against numba: counts, offsets and sorted order bit for bit; neighbour sets exactly."""
import numpy as np
import pytest
from conftest import BACKENDS

from sphcore.backends import STATUS_CLEAR, NumbaBackend, Stage, empty_state, plan
from sphcore.params import pyramid_levels
from sphcore.scene import Scene
from sphcore.simulation import Simulation, SimulationError

BOX = 0.3


def scene_for(dim, search="grid", boundary="walls", spacing=0.02, ratio=2.0):
    """A box of side BOX; h = ratio x spacing (from 3 x spacing on, cells of h / 2: Scene.cell_split)."""
    return Scene.from_dict({
        "physics": {"model": "graphics", "dimension": dim, "neighbour_search": search},
        "domain": {"box_min": [0.0] * dim, "box_max": [BOX] * dim, "boundary": boundary},
        "fluid": {"blocks": [{"min": [0.0] * dim, "max": [0.1] * dim}], "spacing": spacing, "smoothing_ratio": ratio},
    })


def neighbour_fingerprints(x, ids, h, box_min, box_max, walls=True):
    """All-pairs reference of compute_density's neighbour statistics: for each i, the number of
    (j, image) with r^2 < h^2 (self included) and the wrapped sum of their hashes. Distances in
    float32 with the shader's operation order, so set membership is exact, not approximate."""
    x = x.astype(np.float32)
    h = np.float32(h)
    n, dim = x.shape
    counts = np.zeros(n, np.int64)
    prints = np.zeros(n, np.uint64)
    for i in range(n):
        wall = np.where(x[i] - box_min < h, box_min, box_max).astype(np.float32)
        mirrored = [axis for axis in range(dim) if walls and abs(x[i, axis] - wall[axis]) < h]
        for image in range(8):
            if any(image >> a & 1 and a not in mirrored for a in range(3)):
                continue
            xk = x.copy()
            for a in range(dim):
                if image >> a & 1:
                    xk[:, a] = np.float32(2.0) * wall[a] - x[:, a]
            r = x[i] - xk
            r2 = r[:, 0] * r[:, 0] + r[:, 1] * r[:, 1]
            if dim == 3:
                r2 = r2 + r[:, 2] * r[:, 2]
            else:
                r2 = r2 + np.float32(0.0) * np.float32(0.0)
            near = np.flatnonzero(r2 < h * h)
            counts[i] += len(near)
            k = ids[near].astype(np.uint64) * 8 + image
            hsh = (k * 0x9E3779B1) & 0xFFFFFFFF
            hsh ^= hsh >> 15
            hsh = (hsh * 0x85EBCA77) & 0xFFFFFFFF
            hsh ^= hsh >> 13
            prints[i] = (prints[i] + hsh.sum()) & 0xFFFFFFFF
    return counts, prints


def layouts(dim, cell, rng):
    """name -> positions (n, dim): the lattice jittered, and the adversarial cases (`cell`: the grid's side)."""
    lattice = np.stack(np.meshgrid(*[np.arange(0.01, 0.11, 0.02)] * dim, indexing="ij"), -1).reshape(-1, dim)
    faces = np.stack(np.meshgrid(*[np.arange(0, 4) * cell] * dim, indexing="ij"), -1).reshape(-1, dim)
    return {
        "jittered_lattice": lattice + rng.uniform(-0.008, 0.008, lattice.shape),
        "one_cell": 0.5 * cell + rng.uniform(-0.4, 0.4, (60, dim)) * cell,
        "cell_faces": faces,  # on the faces, edges and corners of cells, and on the walls x = 0
        "walls_and_corners": np.concatenate([np.zeros((3, dim)), np.full((2, dim), BOX),
                                             rng.uniform(0, BOX, (20, dim)) * (rng.random((20, dim)) < 0.5)]),
        "far_apart": rng.uniform(0, BOX, (40, dim)),  # mostly empty cells
        "one_particle": np.full((1, dim), 0.05),
        "none": np.zeros((0, dim)),
    }


def load(scene, x):
    params = scene.params(len(x))
    state = empty_state(params)
    state["particle_x"][:, :scene.dim] = x
    return params, state


def stats_spec(scene):
    return scene.spec._replace(NEIGHBOUR_STATS=True)


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("split", [1, 2])
def test_grid_neighbour_sets_equal_all_pairs_exactly(open_backend, backend, dim, split):
    """Split 2: h = 4 dx, cells of h / 2, the 5^dim cells around a particle's searched (Scene.cell_split)."""
    rng = np.random.default_rng(dim)
    scene = scene_for(dim, ratio=2.0 * split)
    assert scene.cell_split == split and scene.spec.CELL_SPLIT == split
    for name, x in layouts(dim, scene.cell_size, rng).items():
        x = np.clip(x, 0.0, BOX).astype(np.float32)
        params, state = load(scene, x)
        sim = open_backend(backend, params, state, plan(scene), stats_spec(scene))
        for stage in plan(scene)[:-2]:  # the sort, then compute_density
            sim.run_stage(stage)
        s = sim.read()
        ids = s["particle_id"]
        np.testing.assert_array_equal(np.sort(ids), np.arange(len(x)), err_msg=f"{name}: particles lost or doubled")
        counts, prints = neighbour_fingerprints(x[ids], ids, scene.h, np.zeros(dim, np.float32),
                                                np.full(dim, BOX, np.float32))
        np.testing.assert_array_equal(s["particle_neighbours"][:, 0], counts, err_msg=f"{name}: neighbour counts")
        np.testing.assert_array_equal(s["particle_neighbours"][:, 1], prints, err_msg=f"{name}: neighbour sets")
        sim.close()


@pytest.mark.parametrize("split", [1, 2])
def test_open_domain_neighbour_sets_equal_all_pairs_exactly(split):
    """Hashed cells: particles a whole period apart share cells but are never counted together."""
    scene = scene_for(3, boundary="open", ratio=2.0 * split)
    assert scene.cell_split == split
    rng = np.random.default_rng(7)
    x = rng.uniform(-0.5, 0.8, (300, 3)).astype(np.float32)  # over several hash periods
    params, state = load(scene, x)
    backend = NumbaBackend(params, state, plan(scene), stats_spec(scene))
    for stage in plan(scene)[:-2]:
        backend.run_stage(stage)
    s = backend.read()
    ids = s["particle_id"]
    counts, prints = neighbour_fingerprints(x[ids], ids, scene.h, np.zeros(3, np.float32), np.full(3, BOX, np.float32),
                                            walls=False)
    assert counts.max() > 1, "no pairs: the test would not see a miss"
    np.testing.assert_array_equal(s["particle_neighbours"][:, 0], counts)
    np.testing.assert_array_equal(s["particle_neighbours"][:, 1], prints)
    assert s["grid_status"][0] == 0


def test_sorted_order_is_by_cell_then_index_and_offsets_match_counts():
    scene = scene_for(3)
    x = np.random.default_rng(3).uniform(0, BOX, (500, 3)).astype(np.float32)
    params, state = load(scene, x)
    backend = NumbaBackend(params, state, plan(scene), scene.spec)
    for stage in plan(scene):
        if stage.name == "gather_particles":
            break
        backend.run_stage(stage)
    s = backend.read()
    cells = s["particle_cell"].astype(np.int64)
    dims = np.array(scene.grid_dim)
    expected = np.minimum(np.floor(x / np.float32(1 / params[0]["inv_cell"])).astype(np.int64), dims - 1)
    np.testing.assert_array_equal(cells, (expected[:, 2] * dims[1] + expected[:, 1]) * dims[0] + expected[:, 0])
    counts = np.bincount(cells, minlength=int(np.prod(dims)))
    np.testing.assert_array_equal(s["cell_pyramid"][:len(counts)], counts)
    np.testing.assert_array_equal(s["cell_start"], np.concatenate([[0], np.cumsum(counts)[:-1]]))
    # each cell layer (z, the slowest index) starts after the particles of the layers below it
    layers = np.bincount(expected[:, 2], minlength=dims[2])
    np.testing.assert_array_equal(s["layer_start"][:dims[2]], np.concatenate([[0], np.cumsum(layers)[:-1]]))
    # every pyramid level sums its 8 children; the top holds n
    levels, total = pyramid_levels(len(counts))
    assert len(s["cell_pyramid"]) == total and s["cell_pyramid"][-1] == len(x)
    np.testing.assert_array_equal(s["sorted_index"], np.lexsort((np.arange(len(x)), cells)))


@pytest.mark.parametrize("dim", [2, 3])
def test_vulkan_sort_is_bitwise_the_numba_sort(open_backend, dim):
    """Counts, pyramid, offsets and sorted order equal bit for bit, whatever order the GPU's
    atomics handed out the slots in (several steps, so particles move between cells)."""
    scene = Scene.from_dict({
        "physics": {"model": "graphics", "dimension": dim},
        "domain": {"box_min": [0.0] * dim, "box_max": [0.4] * dim},
        "fluid": {"blocks": [{"min": [0.0] * dim, "max": [0.16, 0.2, 0.16][:dim]}], "spacing": 0.02},
    })
    x = scene.initial_positions() + np.random.default_rng(1).uniform(-0.005, 0.005, (len(scene.initial_positions()), dim))
    params, state = load(scene, np.clip(x, 0, 0.4).astype(np.float32))
    out = {}
    for name in BACKENDS:
        b = open_backend(name, params, state, plan(scene), scene.spec)
        b.step(20)
        for stage in plan(scene)[:-3]:
            b.run_stage(stage)
        out[name] = b.read()
    for key in ("particle_id", "particle_cell", "cell_pyramid", "cell_start", "sorted_index", "grid_status",
                "layer_start"):
        np.testing.assert_array_equal(out["numba"][key], out["vulkan"][key], err_msg=key)
    layers = np.bincount(np.floor(out["numba"]["particle_x"][:, dim - 1] * params[0]["inv_cell"]).astype(np.int64))
    assert np.count_nonzero(layers) > 2  # (layers of particles, their starts compared above)


@pytest.mark.parametrize("backend", BACKENDS)
def test_grid_and_all_pairs_densities_agree(open_backend, backend):
    """Same neighbours, different summation order: float32 rounding only (~1e-7 per term)."""
    rho = {}
    for search in ("grid", "all_pairs"):
        scene = scene_for(3, search)
        x = np.random.default_rng(4).uniform(0, 0.12, (400, 3)).astype(np.float32)
        params, state = load(scene, x)
        b = open_backend(backend, params, state, plan(scene), scene.spec)
        for stage in plan(scene)[:-2]:
            b.run_stage(stage)
        s = b.read()
        rho[search] = s["particle_rho"][np.argsort(s["particle_id"])]
    np.testing.assert_allclose(rho["grid"], rho["all_pairs"], rtol=1e-5)
    assert rho["grid"].max() > 2 * rho["grid"].min(), "uniform densities: the test would not see a missed pair"


@pytest.mark.parametrize("backend", BACKENDS)
def test_particle_outside_the_hashed_range_is_reported(open_backend, backend):
    """Never dropped silently: the grid counts it, names it, and the run stops with a message."""
    scene = scene_for(3, boundary="open")
    x = np.random.default_rng(5).uniform(0.1, 0.2, (50, 3)).astype(np.float32)
    x[17] = (1e9, 0.1, 0.1)  # 5e10 cells away: beyond the +-2^24 cells a float32 coordinate resolves
    x[30, 1] = np.nan
    params, state = load(scene, x)
    b = open_backend(backend, params, state, plan(scene), scene.spec)
    b.step(1)
    s = b.read()
    assert s["grid_status"][0] >= 2 and s["grid_status"][1] == 17
    assert sorted(s["particle_id"]) == list(range(50)), "a particle was dropped"
    b.clear_status()
    np.testing.assert_array_equal(b.read()["grid_status"], STATUS_CLEAR)


def test_simulation_names_the_particle_that_left_the_hashed_range():
    scene = scene_for(3, boundary="open")
    sim = Simulation(scene, "numba")
    slot = int(np.flatnonzero(sim.backend.state["particle_id"] == 3)[0])  # the start is sorted by cell already
    sim.backend.state["particle_x"][slot, 0] = 3e9
    sim.advance(1)
    with pytest.raises(SimulationError, match=r"hashed range.*particle 3\b"):
        sim.check_grid(sim.backend.read()["grid_status"])


def test_plan_without_surface_tension_has_no_surface_tension_work():
    scene = Scene.load("scenes/dam_break_3d.toml")
    assert not scene.spec.SURFACE_TENSION
    assert all("surface" not in s.name and "cohesion" not in s.name for s in plan(scene))
    droplet = Scene.load("scenes/droplet_3d.toml")
    assert droplet.spec.SURFACE_TENSION and not droplet.spec.GRAVITY and not droplet.spec.WALLS
    # all pairs: no grid stage at all; the grid: count, one reduction per pyramid level, offsets, sort
    tank = Scene.load("scenes/tank_3d.toml")  # the default (graphics) model: no density or dt stages
    all_pairs = Scene.from_dict({**tank.config, "physics": {**tank.config["physics"], "neighbour_search": "all_pairs"}})
    assert [s.name for s in plan(all_pairs)] == ["compute_density", "compute_forces", "integrate"]
    # the engineering model of dam_break_3d adds the continuity density and the device's dt
    assert [s.name for s in plan(scene) if s.name not in {t.name for t in plan(tank)}] == [
        "integrate_density", "reduce_dt", "choose_dt"]
    levels = pyramid_levels(int(np.prod(scene.grid_dim)))[0]
    assert [s.level for s in plan(scene) if s.name == "reduce_cells"] == list(range(1, levels + 1))
    assert Stage("count_cells") in plan(scene)


def test_disabled_terms_are_compiled_out_of_the_mirror():
    """A closure constant removes the term: with viscosity off, the mirror ignores fluid.viscosity."""
    base = {"domain": {"box_min": [0, 0], "box_max": [0.3, 0.3]}, "forces": {"gravity": [0.0, 0.0]},
            "fluid": {"blocks": [{"min": [0.05, 0.05], "max": [0.15, 0.15]}], "spacing": 0.02, "viscosity": 50.0}}
    acc = {}
    for on in (True, False):
        scene = Scene.from_dict({**base, "physics": {"model": "graphics", "viscosity": on}})
        sim = Simulation(scene, "numba")
        sim.backend.state["particle_v"][:, 0] = np.linspace(-1, 1, sim.n)
        for stage in sim.stages[:-1]:
            sim.backend.run_stage(stage)
        acc[on] = sim.backend.read()["particle_a"]
    assert np.abs(acc[True] - acc[False]).max() > 1.0
