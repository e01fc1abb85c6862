"""The plan of a step, apart from the backends that run it (sphcore.backends): the buffers (`BUFFERS`,
binding number = index), the stages with their mirrors and the buffers each binds (`STAGES`), and
`plan(scene)`, the ordered stages one step of a scene runs, the pressure solver's among them
(sphcore.solvers); and the helpers that size, make and read the buffers.
"""
import numpy as np

from sphcore.gauges import GAUGE_SLOTS, LAYER_SLOTS
from sphcore.params import MAX_OBSTACLES, pyramid_levels
from sphcore.solvers import solver_for
from sphcore.sph.apply_order import apply_order
from sphcore.sph.cell_offsets import cell_offsets
from sphcore.sph.choose_dt import choose_dt
from sphcore.sph.clear_cells import clear_cells
from sphcore.sph.compute_density import compute_density
from sphcore.sph.compute_forces import compute_forces
from sphcore.sph.count_cells import count_cells
from sphcore.sph.dfsph import CONTROL_REBUILD, CONTROL_SIZE, list_width
from sphcore.sph.dfsph_factor import dfsph_factor
from sphcore.sph.dfsph_predict import dfsph_predict
from sphcore.sph.dfsph_residual import dfsph_residual
from sphcore.sph.dfsph_velocity import dfsph_velocity
from sphcore.sph.gather_particles import gather_particles
from sphcore.sph.integrate import integrate
from sphcore.sph.integrate_density import integrate_density
from sphcore.sph.pack_rows import pack_rows
from sphcore.sph.pick_groups import pick_groups
from sphcore.sph.pick_rows import pick_rows
from sphcore.sph.place_rows import place_rows
from sphcore.sph.reduce_cells import reduce_cells
from sphcore.sph.reduce_dt import reduce_dt
from sphcore.sph.sample_gauges import sample_gauges
from sphcore.sph.scatter_particles import scatter_particles
from sphcore.sph.sort_cells import sort_cells
from sphcore.sph.wall_pressure import wall_pressure
from sphcore.stage import ALWAYS, BUILD, REUSE, Stage  # noqa: F401 (sphcore.plan.ALWAYS)

PICK_ENTRIES = 32  # the ranks one rank's exchange sends rows to, at most (pick_rows.comp)
REAL = "real"  # a buffer of the shaders' `real`: float32 or float64, as the precision says
PRECISIONS = ("float32", "float64")

# binding number = index: name -> (dtype, components, length: "particles" | "cells" | "pyramid" | "neighbours"
# (DFSPH's list slots) | "layers" (of cells, along the grid's slowest axis) | count)
BUFFERS = {
    "particle_x": (REAL, 4, "particles"),
    "particle_v": (REAL, 4, "particles"),
    "particle_a": (REAL, 4, "particles"),
    "particle_rho": (REAL, 1, "particles"),
    "particle_p": (REAL, 1, "particles"),
    "particle_id": (np.uint32, 1, "particles"),
    "particle_cell": (np.uint32, 1, "particles"),
    "particle_slot": (np.uint32, 1, "particles"),
    "cell_pyramid": (np.uint32, 1, "pyramid"),
    "cell_start": (np.uint32, 1, "cells"),
    "sorted_index": (np.uint32, 1, "particles"),
    "scratch_x": (REAL, 4, "particles"),
    "scratch_v": (REAL, 4, "particles"),
    "scratch_id": (np.uint32, 1, "particles"),
    "grid_status": (np.uint32, 1, 4),
    "particle_neighbours": (np.uint32, 2, "particles"),
    "obstacle_box": (np.float32, 4, 2 * MAX_OBSTACLES),
    "particle_drho": (REAL, 1, "particles"),
    "scratch_rho": (REAL, 1, "particles"),
    "particle_vh": (REAL, 4, "particles"),
    "time_state": (np.float32, 4, 1),
    "dt_partial": (REAL, 2, "particles"),
    "particle_alpha": (REAL, 1, "particles"),
    "particle_residual": (REAL, 1, "particles"),
    "control": (np.uint32, 1, CONTROL_SIZE),
    "dfsph_state": (np.float32, 1, 8),
    "dfsph_history": (np.float32, 8, 256),
    "particle_kappa": (REAL, 1, "particles"),
    "dfsph_partial": (REAL, 1, "particles"),
    "neighbours": (np.uint32, 1, "neighbours"),
    "neighbour_count": (np.uint32, 1, "particles"),
    "neighbour_gradients": (REAL, 4, "gradients"),
    "gauge_table": (np.float32, 4, "gauge_rows"),
    "gauge_state": (np.uint32, 4, "gauge_rows"),
    "gauge_samples": (REAL, 4, "gauge_samples"),
    "pick_table": (np.uint32, 4, 1 + PICK_ENTRIES),
    "pick_bounds": (np.float32, 4, PICK_ENTRIES),
    "pick_count": (np.uint32, 1, 2 * PICK_ENTRIES),
    "layer_start": (np.uint32, 1, "layers"),
    "gauge_layers": (REAL, 4, "gauge_layers"),
    "scratch_vh": (REAL, 4, "particles"),
    "received": (np.uint32, 1, 2),
    "place_table": (np.uint32, 4, 1 + PICK_ENTRIES),
    "sent": (np.uint32, 1, 2),
    "band_rows": (np.uint32, 2, 1 + PICK_ENTRIES),
    "rank_groups": (np.uint32, 4, 2),
}
# particle_kappa: DFSPH's stiffness sum of the last constant-density solve, the next one's warm start
# (sorted with the particles, with scratch_rho as its scratch: DFSPH has no continuity density).
# particle_alpha, particle_residual: DFSPH's factor alpha_i and the residual r_i of the solve in progress;
# scratch_v, the sort's scratch, holds v* = v + dt a during DFSPH's constant-density solve (dfsph_predict);
# dfsph_partial: the sum of each dfsph_residual work group's residuals (as many as particles: local size 1);
# neighbours, neighbour_count: each particle's neighbour list for the solves' sweeps, written by
# dfsph_factor (spec.MAX_NEIGHBOURS slots a particle, rounded up to whole chunks of 4, dfsph.list_width:
# "neighbours" is n times that, at least 1 word);
# neighbour_gradients: with spec.GRADIENTS (DFSPH on numba), each list entry's V grad_i W, which dfsph_factor
# writes in the list's layout: a pair's distance, direction and kernel are computed once a step, not in every
# sweep ("gradients" is as long as "neighbours" then, else 1).
# control, dfsph_state, dfsph_history: its iteration control, tolerances and errors, and one row per
# step (layouts in shaders/sph/dfsph.glsl; physics.pressure_solver = "dfsph").
# particle_vh: time.integrator = "verlet"'s half-step velocity v_{n+1/2} (shaders/sph/integrators.glsl); under
# DFSPH, which never runs Verlet, the sum of a particle's list entries' V grad_i W (dfsph_factor writes it,
# dfsph_residual reads it: particle_gradient_sum there).
# time_state: (dt, the last step's dt, time hi, time lo) written on the device by choose_dt (with
# time.dt = "adaptive" or "verlet"; zero at the start); the time is hi + lo (a compensated float32 sum).
# dt_partial: reduce_dt's largest (|v|^2, |a|^2) per work group (as many as particles: local size 1).
# grid_status: [0] particles found outside the grid's range, [1] the lowest id among them,
# [2] steps whose pyramid total differed from n. Cleared by the host, accumulated by the shaders.
# gauge_table, gauge_state: two rows per gauge of the scene's [[gauges]] (sphcore.gauges.table;
# shaders/sph/sample_gauges.comp): gauge_table (the point, the interval), (about or the height's step, the mass);
# gauge_state (quantity, the body's first id or a height's axis, the body's count, the ring's size GAUGE_SLOTS),
# (the next multiple of the interval, samples taken); gauge_samples: GAUGE_SLOTS rows (time, value x, y, z) a gauge,
# a ring the host reads before it can fill ("gauge_rows": 2 per gauge, "gauge_samples": GAUGE_SLOTS per gauge; at
# least 1 gauge's: a state without gauges has a gauge_state of zeros, which sample_gauges skips).
# pick_table, pick_bounds, pick_count: a rank's exchange (sphcore.parallel; shaders/sph/pick_rows.comp): the number of
# entries and the rows held, then a row an entry (another rank): the layers whose rows it may need (first, end) and
# its slab's layers (first, end); the slab widened by the halo's width (lowest, highest coordinate); the migrants and
# the halo rows picked for it.
# layer_start: the first row of each cell layer (the grid's slowest index) after the sort (cell_offsets), which a
# rank reads after a step (sphcore.parallel: Rank.starts).
# scratch_vh: a rank's pick of Verlet's half-step velocities (pick_rows.comp: the step's last stage, after which
# particle_a holds the step's accelerations, as a checkpoint keeps them).
# received, place_table: a rank's rows pulled from GPU to GPU (place_rows.comp): on Vulkan the peers' inbox is bound
# in received's place (backend.bind_words; numba: the bytes' array); the table: the senders, the owned rows' first
# and end, the rows received, then a row a sender (its first word, its migrants and halo rows).
# band_rows, rank_groups: on a rank, the rows its pick reads (the entries' first row and count, after their number),
# which pick_groups writes after the sort for compute_forces' two passes and pick_rows (the host writes the pick's
# table for the next step while the second pass runs: sphcore.parallel); the (x, y, z) work groups of the indirect
# dispatches of one invocation a row (backends.RANK_GROUPS) and the rows: [0] those (pick_groups), [1] the rows
# received (place_rows: the host writes them).
# sent: the rows a rank sends from GPU to GPU (pack_rows.comp: those pick_count counts, laid out from the pick's
# table), the peers' outbox bound in its place.
# gauge_layers: on a rank, a force or moment gauge's sum over each cell layer, a ring of LAYER_SLOTS samples a gauge
# (sample_gauges.comp; "gauge_layers": LAYER_SLOTS rows of "layers" a gauge, at least 1 gauge's).
# obstacle_box: min and max corner of each box obstacle (domain.obstacles), z = 0 in 2D; the first
# spec.OBSTACLES pairs are read (float32, like the parameter block's walls).
STATUS_CLEAR = np.array([0, 0xFFFFFFFF, 0, 0], np.uint32)

# stage -> (mirror factory, invocations: "particles" | "cells" | "nodes" | "one" | "gauges", buffers its shader binds
# in order; a stage's pipeline binds these only, each at its index in BUFFERS)
STAGES = {
    "clear_cells": (clear_cells, "cells", ("cell_pyramid",)),
    "count_cells": (count_cells, "particles", ("particle_x", "particle_id", "particle_cell", "particle_slot",
                                               "cell_pyramid", "grid_status")),
    "reduce_cells": (reduce_cells, "nodes", ("cell_pyramid",)),
    "cell_offsets": (cell_offsets, "cells", ("cell_pyramid", "cell_start", "grid_status", "layer_start")),
    "scatter_particles": (scatter_particles, "particles", ("particle_cell", "particle_slot", "cell_start",
                                                           "sorted_index")),
    "sort_cells": (sort_cells, "cells", ("cell_pyramid", "cell_start", "sorted_index", "particle_id")),
    "gather_particles": (gather_particles, "particles", ("particle_x", "particle_v", "particle_id", "sorted_index",
                                                         "scratch_x", "scratch_v", "scratch_id", "particle_rho",
                                                         "scratch_rho", "particle_a", "particle_vh",
                                                         "particle_kappa")),
    "apply_order": (apply_order, "particles", ("particle_x", "particle_v", "particle_id", "scratch_x",
                                               "scratch_v", "scratch_id", "particle_rho", "scratch_rho",
                                               "particle_a", "particle_vh", "particle_kappa")),
    "compute_density": (compute_density, "particles", ("particle_x", "particle_v", "particle_rho", "particle_p",
                                                       "cell_pyramid", "cell_start", "scratch_x", "particle_id",
                                                       "particle_neighbours", "obstacle_box", "particle_drho",
                                                       "control", "neighbours", "neighbour_count")),
    "compute_forces": (compute_forces, "particles", ("particle_x", "particle_v", "particle_a", "particle_rho",
                                                     "particle_p", "particle_id", "cell_pyramid", "cell_start", "scratch_x",
                                                     "obstacle_box", "control", "neighbours",
                                                     "neighbour_count", "scratch_v", "band_rows")),
    "wall_pressure": (wall_pressure, "particles", ("particle_x", "particle_v", "particle_rho", "particle_p",
                                                   "particle_id", "cell_pyramid", "cell_start", "scratch_x",
                                                   "obstacle_box", "neighbours", "neighbour_count")),
    "reduce_dt": (reduce_dt, "particles", ("particle_v", "particle_a", "dt_partial", "particle_id", "cell_start")),
    "choose_dt": (choose_dt, "one", ("time_state", "dt_partial")),
    "dfsph_factor": (dfsph_factor, "particles", ("particle_x", "particle_p", "obstacle_box", "particle_alpha",
                                                 "control", "dfsph_state", "particle_kappa", "neighbours",
                                                 "neighbour_count", "neighbour_gradients", "particle_vh")),
    "dfsph_predict": (dfsph_predict, "particles", ("particle_v", "particle_a", "scratch_v", "time_state")),
    "dfsph_residual": (dfsph_residual, "particles", ("particle_x", "particle_v", "scratch_v", "particle_rho",
                                                     "obstacle_box", "time_state", "particle_residual",
                                                     "dfsph_partial", "neighbours", "neighbour_count",
                                                     "neighbour_gradients", "control", "dfsph_state",
                                                     "dfsph_history", "particle_vh")),
    "dfsph_velocity": (dfsph_velocity, "particles", ("particle_x", "particle_v", "particle_a", "particle_rho",
                                                     "particle_p", "obstacle_box", "time_state", "particle_alpha",
                                                     "particle_residual", "control", "particle_kappa",
                                                     "neighbours", "neighbour_count", "neighbour_gradients",
                                                     "scratch_v")),
    "integrate": (integrate, "particles", ("particle_x", "particle_v", "particle_a", "scratch_x", "obstacle_box",
                                           "particle_vh", "time_state", "control", "scratch_v", "particle_id")),
    "integrate_density": (integrate_density, "particles", ("particle_rho", "particle_p", "particle_drho",
                                                           "time_state")),
    "sample_gauges": (sample_gauges, "gauges", ("particle_x", "particle_v", "particle_a", "particle_rho",
                                                "particle_p", "particle_id", "cell_pyramid", "cell_start",
                                                "time_state", "gauge_table", "gauge_state", "gauge_samples",
                                                "layer_start", "gauge_layers")),
    "pick_rows": (pick_rows, "particles", ("particle_x", "particle_v", "particle_a", "particle_rho", "particle_id",
                                           "particle_vh", "obstacle_box", "time_state", "scratch_x", "scratch_v",
                                           "scratch_id", "scratch_rho", "scratch_vh", "pick_table", "pick_bounds",
                                           "pick_count", "layer_start", "band_rows")),
    "pick_groups": (pick_groups, "one", ("pick_table", "layer_start", "band_rows", "rank_groups")),
    "pack_rows": (pack_rows, "particles", ("scratch_x", "scratch_v", "scratch_id", "scratch_rho", "scratch_vh",
                                           "sent", "pick_table", "pick_count", "layer_start")),
    "place_rows": (place_rows, "particles", ("particle_x", "particle_v", "particle_rho", "particle_id", "particle_vh",
                                             "received", "place_table")),
}

def neighbour_stages(cell_total):
    """The grid's stages: count particles per cell, reduce the pyramid, offsets, sort."""
    levels = pyramid_levels(cell_total)[0]
    return ([Stage("clear_cells"), Stage("count_cells")]
            + [Stage("reduce_cells", level) for level in range(1, levels + 1)]
            + [Stage("cell_offsets"), Stage("scatter_particles"), Stage("sort_cells"),
               Stage("gather_particles"), Stage("apply_order")])


def density_stages(scene):
    """The stages of a step up to its density (Simulation.compute_densities runs them alone): with the grid
    the sort, then compute_density, integrate_density where the density is state (continuity), and the bodies'
    wall particles' pressure from the fluid's (wall_pressure)."""
    spec = scene.spec
    stages = neighbour_stages(int(np.prod(scene.grid_dim))) if spec.GRID else []
    stages += [Stage("compute_density")]
    # lists reused between builds (physics.list_skin): the sort and the scan only at a build, else the walk
    # (compute_density at level 1); compute_forces clears the request that integrate sets (cells.glsl)
    if spec.LIST_SKIN:
        stages = [s._replace(when=BUILD) for s in stages] + [Stage("compute_density", 1, when=REUSE)]
    stages += [Stage("integrate_density")] if spec.CONTINUITY else []  # the density is state (continuity)
    return stages + ([Stage("wall_pressure")] if spec.BODIES else [])  # the bodies' wall particles (Adami 2012)


def plan(scene):
    """The ordered stages one time step of `scene` runs; both backends execute this list with
    the specialization constants `scene.spec` (a disabled term is compiled out of its shader)."""
    spec, solver = scene.spec, solver_for(scene)
    # the pressure solver's stages before the forces, and once the step's dt is known (sphcore.solvers)
    stages = density_stages(scene) + solver.stages_before_forces() + [Stage("compute_forces")]
    # the gauges (scene [[gauges]]): after the forces, before choose_dt, where positions, velocities, densities,
    # pressures, accelerations and the time in time_state are all of the step's start, t_n
    gauges = bool(scene.config.get("gauges"))
    stages += [Stage("sample_gauges")] if gauges else []
    # the step's dt on the device (time.dt = "adaptive"), and the last step's for Verlet; the time for the gauges
    stages += [Stage("reduce_dt")] if spec.ADAPTIVE_DT else []
    stages += [Stage("choose_dt")] if spec.ADAPTIVE_DT or spec.VERLET or gauges else []
    return stages + solver.stages_after_dt() + [Stage("integrate")]


def buffer_dtype(name, precision="float32"):
    """The numpy dtype of buffer `name` at `precision` ("float32" or "float64")."""
    if precision not in PRECISIONS:
        raise ValueError(f"unknown precision {precision!r}: choose one of {', '.join(PRECISIONS)}")
    dtype = BUFFERS[name][0]
    return np.dtype(precision if dtype == REAL else dtype)


def row_bytes(name, precision="float32"):
    """The bytes of one row (a particle's, a cell's, ...) of buffer `name` at `precision`."""
    return buffer_dtype(name, precision).itemsize * BUFFERS[name][1]


def buffer_length(length, params, max_neighbours=0, gradients=False, gauges=0):
    """Elements of a buffer of BUFFERS' `length` for the parameter block `params` (and the
    spec.MAX_NEIGHBOURS list slots a particle; `gradients`: DFSPH stores their gradients, spec.GRADIENTS;
    `gauges`: the scene's gauges)."""
    if length == "gauge_rows":
        return 2 * max(1, gauges)
    if length == "gauge_samples":
        return GAUGE_SLOTS * max(1, gauges)
    if length == "gauge_layers":
        return LAYER_SLOTS * max(1, gauges) * buffer_length("layers", params)
    if length == "particles":
        return int(params[0]["n"])
    if length == "neighbours":
        return max(1, int(params[0]["n"]) * list_width(max_neighbours))
    if length == "gradients":
        return max(1, int(params[0]["n"]) * list_width(max_neighbours)) if gradients else 1
    if length == "cells":
        return int(params[0]["cell_total"])
    if length == "pyramid":
        return pyramid_levels(int(params[0]["cell_total"]))[1]
    if length == "layers":
        return int(params[0]["grid_dim"].max())  # (room for the layers along any axis: the slowest's, 2D or 3D)
    return length


def empty_state(params, precision="float32", obstacles=(), max_neighbours=0, gradients=False, gauges=None):
    """Zeroed buffers for `params` (ids 0..n-1, grid status cleared), real-valued ones at `precision`,
    neighbour lists of `max_neighbours` slots a particle (a scene's spec.MAX_NEIGHBOURS; with `gradients`,
    spec.GRADIENTS, also room for DFSPH's gradient of each entry),
    and the box `obstacles` ([{"min": [...], "max": [...]}], a scene's domain.obstacles) in obstacle_box;
    `gauges`: (gauge_table, gauge_state) of sphcore.gauges.table, the scene's gauges.
    A box's face that lies on a wall is no face: the box is continued through the wall by the tank's
    size (a box on the floor reaches below it), so that no particle slides between the two on the
    wall, and none inside the box is put back out through the wall (integrate.comp)."""
    state = {}
    count = 0 if gauges is None else len(gauges[0]) // 2
    for name, (_, c, length) in BUFFERS.items():
        k = buffer_length(length, params, max_neighbours, gradients, count)
        state[name] = np.zeros((k, c) if c > 1 else k, buffer_dtype(name, precision))
    if gauges is not None:
        state["gauge_table"][:], state["gauge_state"][:] = gauges
    state["particle_id"][:] = np.arange(len(state["particle_id"]))
    state["grid_status"][:] = STATUS_CLEAR
    state["control"][CONTROL_REBUILD] = 1  # (reused lists, spec.LIST_SKIN: the first step builds them)
    if len(obstacles) > MAX_OBSTACLES:
        raise ValueError(f"{len(obstacles)} obstacles: the obstacle_box buffer holds at most {MAX_OBSTACLES}")
    wall_lo, wall_hi = params[0]["box_min"], params[0]["box_max"]
    for k, box in enumerate(obstacles):
        state["obstacle_box"][2 * k, :len(box["min"])] = box["min"]
        state["obstacle_box"][2 * k + 1, :len(box["max"])] = box["max"]
        lo, hi = state["obstacle_box"][2 * k, :3], state["obstacle_box"][2 * k + 1, :3]
        lo[:] = np.where(lo <= wall_lo, wall_lo - (wall_hi - wall_lo), lo)
        hi[:] = np.where(hi >= wall_hi, wall_hi + (wall_hi - wall_lo), hi)
    return state


def list_entries(state, spec, name="neighbours"):
    """Buffer `name` of the neighbour lists (neighbours, or neighbour_gradients) of a state run with `spec`,
    as (particles, spec.MAX_NEIGHBOURS[, 4]) in particle order of the buffers: either layout (list_slot)."""
    n, slots = len(state["particle_id"]), spec.MAX_NEIGHBOURS
    if spec.LIST_BY_PARTICLE:
        words = np.asarray(state[name])[:n * slots]
        return words.reshape(n, slots, *words.shape[1:])
    if not spec.LIST_CHUNKS:
        words = np.asarray(state[name])[:n * slots]
        return words.reshape(slots, n, *words.shape[1:]).swapaxes(0, 1)
    chunks = list_width(slots) // 4  # (chunk c of particle i: the 4 slots at words 4 (c n + i))
    words = np.asarray(state[name])[:n * 4 * chunks]
    lists = words.reshape(chunks, n, 4, *words.shape[1:]).swapaxes(0, 1)
    return lists.reshape(n, 4 * chunks, *words.shape[1:])[:, :slots]


# The per-particle buffers in_particle_order returns (the state a reader of a run sees).
PARTICLE_BUFFERS = tuple(name for name, (_, c, length) in BUFFERS.items()
                         if length == "particles" and name.startswith("particle_"))


def in_particle_order(state, dim=None):
    """Per-particle arrays ordered by particle id (undoing the grid's sort), vectors cut to `dim`."""
    order = np.argsort(state["particle_id"], kind="stable")
    out = {}
    for name, (_, c, length) in BUFFERS.items():
        if name in PARTICLE_BUFFERS:
            values = state[name][order]
            out[name] = values[:, :dim] if c == 4 and dim else values
    return out
