"""Domain decomposition in slabs (issue 34): which rank owns a particle, which particles it must see as halo,
and where the cuts go. Pure numpy; sphcore.parallel moves the particles between ranks with MPI.

The slabs run along the grid's slowest axis, the last one (cells.glsl, cell_index: (c_z d_y + c_y) d_x + c_x,
so y in 2D, z in 3D): a slab is a run of whole cell layers, and each rank's cells are one contiguous range of
cell indices. Cuts lie on cell boundaries: `cuts` are layer numbers, rank r owns layers cuts[r] .. cuts[r+1]-1
(cuts[0] = 0, cuts[-1] = the layers). A particle below the first layer or above the last (outside a walled box:
the grid then reports it) counts in the nearest one.

Halo: one step of the plan reads neighbours of neighbours. An owned particle's force sums the density and
pressure of particles within h (compute_forces), whose densities (compute_density, and with continuity its
drho, from their own neighbours' positions, velocities and densities) sum over particles within h of them:
positions up to 2 h away along any axis, so along the slab axis too. With reused lists (physics.list_skin = s)
a build lists pairs within (1 + s) h: `halo_width` is 2 (1 + s) h, twice the search's reach (Scene.reach).
Wall images need nothing more: a particle's image across a wall is farther from an owned particle than the
particle itself. With bodies a step reads a third level: a wall particle within h of an owned one gets its pressure
and velocity (wall_pressure, Adami et al. 2012) from the fluid within h of it, whose densities and pressures are
their own neighbours' sums (with continuity from those neighbours' positions, velocities and densities, a wall
particle's among them: state, as its owner wrote it the step before). A height gauge's line takes the point below
each of its points in the slab, half a spacing past the cut at most: the halo reaches that much farther. A rank
sums the densities of the particles it holds up to a reach less than that (summed_width): no step reads a density in
the halo's outermost reach.
"""
import math
import os

import numpy as np

# Launchers' environment variables with the world's size (Open MPI; MPICH's Hydra and Intel MPI, srun with PMI).
# Not SLURM_NTASKS: a job's every process sees it, one started without srun too.
SIZE_VARIABLES = ("OMPI_COMM_WORLD_SIZE", "PMI_SIZE")


def launched_ranks():
    """The ranks mpiexec started this process among (1 where it did not), read from the environment: the CLI
    imports mpi4py only under mpiexec."""
    for name in SIZE_VARIABLES:
        if os.environ.get(name, "").isdigit():
            return int(os.environ[name])
    return 1


DEPTH = 2  # neighbour levels one step reads: forces of owned particles <- densities of neighbours <- positions
BODIES_DEPTH = 3  # with bodies: forces <- a wall particle's pressure <- its fluid's densities <- positions


def depth(scene):
    """The neighbour levels a step of `scene` reads: BODIES_DEPTH where it has bodies, else DEPTH."""
    return BODIES_DEPTH if scene.spec.BODIES else DEPTH


def slab_axis(dim):
    """The axis the slabs are cut along: the grid's slowest (the last: y in 2D, z in 3D)."""
    return dim - 1


MARGIN = 1.01  # the halo's width over DEPTH reaches: the shaders test distances in float32, this module in float64


def halo_width(scene):
    """How far past its slab [m] a rank must see the particles of others for one step: DEPTH (BODIES_DEPTH where
    the scene has bodies) times the reach (and MARGIN); with a height gauge, half a spacing more (its line's point
    below the slab: sample_gauges.comp)."""
    height = any(gauge["quantity"] == "height" for gauge in scene.config.get("gauges", []))
    return (depth(scene) * scene.reach + (scene["fluid.spacing"] / 2 if height else 0.0)) * MARGIN


def summed_width(scene):
    """How far past its slab [m] a rank sums the densities of the particles it holds (compute_density: summed.glsl):
    a reach less than the halo's DEPTH (BODIES_DEPTH) reaches, and MARGIN. The halo's outermost reach is held for
    those sums alone, and a height gauge's points past the slab read positions alone (sample_gauges.comp)."""
    return (depth(scene) - 1) * scene.reach * MARGIN


def layers_of(coordinate, box_min, inv_cell, layers):
    """The cell layer (0 .. layers-1) of each particle's coordinate along the slab axis, as the grid finds it
    (cells.glsl, cell_of: floor((x - box_min) inv_cell) in the coordinate's precision, box_min and inv_cell the
    parameter block's float32): so a rank owns the particles its device's sort puts in its slab's cells.
    Clamped into the grid."""
    x = np.asarray(coordinate)
    real = x.dtype.type if x.dtype in (np.float32, np.float64) else np.float64
    layer = np.floor((x.astype(real) - real(np.float32(box_min))) * real(np.float32(inv_cell)))
    return np.clip(layer, 0, layers - 1).astype(np.int64)


def reach_layers(width, inv_cell):
    """How many cell layers past a slab's cut hold the particles within `width` of it: every particle whose
    coordinate lies less than `width` beyond a cut is in one of them."""
    return math.floor(width * inv_cell) + 1


def bands(cuts, next_cuts, rank, other, reach):
    """The layers of rank `rank`'s slab (under `cuts`, whose particles the last sort put there) that rank `other`
    needs for the next step, under `next_cuts`: (full, halo), full the range of layers (first, end) whose
    particles `other` may own then, halo the two ranges below and above it of those it may see as halo (`reach`
    layers of its slab past each cut: reach_layers). Each reaches a layer farther, the layer a particle may
    cross in a step (sphcore.parallel checks that none went farther: none is lost); every range lies in the slab
    (possibly empty)."""
    lo, hi = cuts[rank], cuts[rank + 1]

    def inside(first, end):
        first, end = min(max(first, lo), hi), min(max(end, lo), hi)
        return first, max(first, end)

    full = inside(next_cuts[other] - 1, next_cuts[other + 1] + 1)
    need = inside(next_cuts[other] - reach - 1, next_cuts[other + 1] + reach + 1)
    return full, [(need[0], full[0]), (full[1], need[1])]


# What a rank's halo row costs a step, in owned rows: it is sorted and its density summed, but its forces and its
# integration are skipped (compute_forces.comp). On a rank of 4 H200s at 33.7 M a held row took about 0.25 us (the
# sort's stages and compute_density), an owned row 0.39 us more (compute_forces, integrate): 0.39 of an owned row's
# 0.64 (benchmarks/results/parallel_gpu/fold_h200x4/profiled/). At 0.5 the end ranks, with one halo, stepped the
# slowest (their stages 6.33 ms against 6.05-6.19 inside); at 0.4 a step took 7.93-8.08 ms against 7.97-8.16
# (pack_h200x4/: halo.json, new.json; three rounds in turns).
HALO_COST = 0.4


def halos(layer_counts, cuts, reach):
    """The particles of each rank's halo under `cuts`: those of the `reach` layers past each of its cuts that
    another rank's slab holds."""
    counts, cuts = np.asarray(layer_counts, np.int64), np.asarray(cuts)
    below = [counts[max(cut - reach, 0):cut].sum() for cut in cuts[:-1]]
    above = [counts[cut:cut + reach].sum() for cut in cuts[1:]]
    return np.array(below) + np.array(above)


def balance(layer_counts, ranks, previous=None, most=None, reach=0):
    """Cuts (ranks + 1 layer numbers) that split the layers, in order, into `ranks` runs of about equal particle
    counts: rank r takes the layers up to where the running count passes (r + 1) / ranks of the total; every
    rank gets at least one layer. With `reach`, about equal work: a rank's own particles and HALO_COST times its
    halo's (`halos`: a rank inside has two, so it owns less than one at an end), the halos those of the cuts of
    equal counts. With `previous` cuts and `most`, each cut moves at most `most` layers from its previous place
    towards that. ValueError where there are fewer layers than ranks."""
    counts = np.asarray(layer_counts, np.int64)
    layers = len(counts)
    if layers < ranks:
        raise ValueError(f"{ranks} ranks but the grid has {layers} cell layers along the slab axis: use at most "
                         f"{layers} ranks")
    running = np.cumsum(counts)

    def cut_at(targets):  # (after the layer whose running count reaches each target)
        return np.concatenate([[0], np.searchsorted(running, targets, side="left") + 1, [layers]])

    cuts = cut_at(running[-1] * np.arange(1, ranks) / ranks)
    if reach:  # again, each rank's share of the work less its halo's
        halo = HALO_COST * halos(counts, cuts, reach)
        cuts = cut_at(np.cumsum((running[-1] + halo.sum()) / ranks - halo)[:-1])
    if previous is not None:
        cuts = np.clip(cuts, np.asarray(previous) - most, np.asarray(previous) + most)
    for r in range(1, ranks):  # at least one layer each, from the bottom up, then from the top down
        cuts[r] = max(cuts[r], cuts[r - 1] + 1)
    for r in range(ranks - 1, 0, -1):
        cuts[r] = min(cuts[r], cuts[r + 1] - 1)
    return cuts


def owners(layer, cuts):
    """The rank that owns each particle of cell layer `layer`."""
    return np.searchsorted(cuts, layer, side="right") - 1


def needed_by(coordinate, owner, cuts, box_min, cell_size, width, rank):
    """Which particles rank `rank` must hold for a step: the ones it owns, and the others (halo) within `width`
    of its slab [box_min + cuts[rank] cell_size, box_min + cuts[rank + 1] cell_size) along the slab axis.
    The first and last slabs reach past the grid (a particle out there is the grid's to report)."""
    x = np.asarray(coordinate, np.float64)
    lo = box_min + cuts[rank] * cell_size if rank > 0 else -np.inf
    hi = box_min + cuts[rank + 1] * cell_size if rank < len(cuts) - 2 else np.inf
    return (owner == rank) | ((x >= lo - width) & (x < hi + width))
