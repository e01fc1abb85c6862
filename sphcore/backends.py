"""The two ways to run the shaders: their numba mirrors (default) and Vulkan.

Both execute the same plan, an ordered list of stages (`plan`), over the same buffers bound
at the same binding numbers (`BUFFERS`), with the same parameter bytes and the same
specialization constants (`Scene.spec`).

With the grid, every step starts by sorting the particles by cell (a counting sort through a
HistoPyramid, seed 2), so the particle buffers are permuted every step; `particle_id` travels
with them and `in_particle_order` undoes the permutation for output.

`precision` (scene key physics.precision, "float32" or "float64") is the type of the real-valued
buffers and of the arithmetic on them: Vulkan builds the shaders with SPHCORE_FLOAT64
(shaders/sph/real.glsl), numba builds the mirrors with `real = np.float64`.
"""
import math
import time
from collections import namedtuple

import numpy as np

from sphcore.params import MAX_OBSTACLES, SHADER_DIR, pyramid_levels
from sphcore.sph.apply_order import apply_order
from sphcore.sph.cell_offsets import cell_offsets
from sphcore.sph.choose_dt import choose_dt
from sphcore.sph.clear_cells import clear_cells
from sphcore.sph.compute_density import can_list_first, compute_density
from sphcore.sph.compute_forces import compute_forces
from sphcore.sph.count_cells import count_cells
from sphcore.sph.dfsph import (CONTROL_DONE, CONTROL_REBUILD, CONTROL_RUNNING, CONTROL_SIZE, CONTROL_STEP,
                               CONTROL_WINDOW, HISTORY_ROWS, NEIGHBOUR_MASK, SOLVE_DENSITY, SOLVE_DIVERGENCE,
                               SOLVE_WARM_START, dispatch_base, list_width)
from sphcore.sph.dfsph_factor import dfsph_factor
from sphcore.sph.dfsph_predict import dfsph_predict
from sphcore.sph.dfsph_residual import dfsph_residual
from sphcore.sph.dfsph_velocity import dfsph_velocity
from sphcore.sph.gather_particles import gather_particles
from sphcore.sph.integrate import integrate
from sphcore.sph.integrate_density import integrate_density
from sphcore.sph.reduce_cells import reduce_cells
from sphcore.sph.reduce_dt import reduce_dt
from sphcore.sph.scatter_particles import scatter_particles
from sphcore.sph.sort_cells import sort_cells
from sphcore.vk_runner.context import STAGING_KEPT
from sphcore.workgroups import group_count

REAL = "real"  # a buffer of the shaders' `real`: float32 or float64, as the precision says
PRECISIONS = ("float32", "float64")

# binding number = index: name -> (dtype, components, length: "particles" | "cells" | "pyramid" | "neighbours"
# (DFSPH's list slots) | count)
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
# obstacle_box: min and max corner of each box obstacle (domain.obstacles), z = 0 in 2D; the first
# spec.OBSTACLES pairs are read (float32, like the parameter block's walls).
STATUS_CLEAR = np.array([0, 0xFFFFFFFF, 0, 0], np.uint32)

# stage -> (mirror factory, invocations: "particles" | "cells" | "nodes", buffers its shader binds in order)
STAGES = {
    "clear_cells": (clear_cells, "cells", ("cell_pyramid",)),
    "count_cells": (count_cells, "particles", ("particle_x", "particle_id", "particle_cell", "particle_slot",
                                               "cell_pyramid", "grid_status")),
    "reduce_cells": (reduce_cells, "nodes", ("cell_pyramid",)),
    "cell_offsets": (cell_offsets, "cells", ("cell_pyramid", "cell_start", "grid_status")),
    "scatter_particles": (scatter_particles, "particles", ("particle_cell", "particle_slot", "cell_start",
                                                           "sorted_index")),
    "sort_cells": (sort_cells, "cells", ("cell_pyramid", "cell_start", "sorted_index")),
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
                                                     "particle_p", "cell_pyramid", "cell_start", "scratch_x",
                                                     "obstacle_box", "control", "neighbours",
                                                     "neighbour_count")),
    "reduce_dt": (reduce_dt, "particles", ("particle_v", "particle_a", "dt_partial")),
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
                                           "particle_vh", "time_state", "control")),
    "integrate_density": (integrate_density, "particles", ("particle_rho", "particle_p", "particle_drho",
                                                           "time_state")),
}

Stage = namedtuple("Stage", "name level indirect when")  # level: the HistoPyramid level a reduce_cells builds,
#   the solve of a DFSPH stage (dfsph.glsl: 1 divergence-free, 2 constant density), compute_density's walk of
#   reused lists (1), else 0; indirect: its work groups are read from control when it runs (indirect_offset),
#   as vkCmdDispatchIndirect does; when: with reused lists (spec.LIST_SKIN), BUILD for a stage that runs only at a
#   build of the lists, REUSE only between builds, as control[CONTROL_REBUILD] says when it runs (on Vulkan
#   by conditional rendering), else ALWAYS
ALWAYS, BUILD, REUSE = 0, 1, 2
Stage.__new__.__defaults__ = (0, False, ALWAYS)


def profile_name(stage):
    """A stage's row in a profile: its name, "compute_density (walk)" for the walk of reused lists."""
    return stage.name + (" (walk)" if stage.when == REUSE else "")


def neighbour_stages(cell_total):
    """The grid's stages: count particles per cell, reduce the pyramid, offsets, sort."""
    levels = pyramid_levels(cell_total)[0]
    return ([Stage("clear_cells"), Stage("count_cells")]
            + [Stage("reduce_cells", level) for level in range(1, levels + 1)]
            + [Stage("cell_offsets"), Stage("scatter_particles"), Stage("sort_cells"),
               Stage("gather_particles"), Stage("apply_order")])


def plan(scene):
    """The ordered stages one time step of `scene` runs; both backends execute this list with
    the specialization constants `scene.spec` (a disabled term is compiled out of its shader)."""
    spec = scene.spec
    stages = neighbour_stages(int(np.prod(scene.grid_dim))) if spec.GRID else []
    stages += [Stage("compute_density")]
    # lists reused between builds (physics.list_skin): the sort and the scan only at a build, else the walk
    # (compute_density at level 1); compute_forces clears the request that integrate sets (cells.glsl)
    if spec.LIST_SKIN:
        stages = [s._replace(when=BUILD) for s in stages] + [Stage("compute_density", 1, when=REUSE)]
    stages += [Stage("integrate_density")] if spec.CONTINUITY else []  # the density is state (continuity)
    # DFSPH (physics.pressure_solver = "dfsph"): the factor and the divergence-free solve before the forces,
    # the constant-density solve once the step's dt is known (dfsph.glsl)
    iterations = scene["fluid.max_iterations"]
    stages += [Stage("dfsph_factor")] + dfsph_solve(SOLVE_DIVERGENCE, iterations) if spec.DFSPH else []
    stages += [Stage("compute_forces")]
    # the step's dt on the device (time.dt = "adaptive"), and the last step's for Verlet
    stages += [Stage("reduce_dt")] if spec.ADAPTIVE_DT else []
    stages += [Stage("choose_dt")] if spec.ADAPTIVE_DT or spec.VERLET else []
    # (v* = v + dt a once dt is known; the warm start where the first residual finds compression, as
    # SPlisHSPlasH's; then the solve)
    stages += [Stage("dfsph_predict"), Stage("dfsph_residual", SOLVE_DENSITY),
               Stage("dfsph_velocity", SOLVE_WARM_START)] + dfsph_solve(SOLVE_DENSITY, iterations) if spec.DFSPH else []
    return stages + [Stage("integrate")]


def dfsph_solve(solve, iterations):
    """One DFSPH solve as recorded: the residual (whose last work group runs the convergence check), then
    `iterations` times an update and the residual, dispatched indirectly. Once a check stops the solve, it
    zeroes their group counts: the loop ends on the device, with no readback, and both backends run the
    same updates."""
    return [Stage("dfsph_residual", solve)] + [Stage(name, solve, True) for name in ("dfsph_velocity",
                                                                                  "dfsph_residual")] * iterations


def indirect_offset(stage):
    """The index in control of an indirect stage's (x, y, z) work group counts (dfsph.glsl)."""
    return dispatch_base(stage.level)


def buffer_dtype(name, precision="float32"):
    """The numpy dtype of buffer `name` at `precision` ("float32" or "float64")."""
    if precision not in PRECISIONS:
        raise ValueError(f"unknown precision {precision!r}: choose one of {', '.join(PRECISIONS)}")
    dtype = BUFFERS[name][0]
    return np.dtype(precision if dtype == REAL else dtype)


def buffer_length(length, params, max_neighbours=0, gradients=False):
    """Elements of a buffer of BUFFERS' `length` for the parameter block `params` (and the
    spec.MAX_NEIGHBOURS list slots a particle; `gradients`: DFSPH stores their gradients, spec.GRADIENTS)."""
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
    return length


def empty_state(params, precision="float32", obstacles=(), max_neighbours=0, gradients=False):
    """Zeroed buffers for `params` (ids 0..n-1, grid status cleared), real-valued ones at `precision`,
    neighbour lists of `max_neighbours` slots a particle (a scene's spec.MAX_NEIGHBOURS; with `gradients`,
    spec.GRADIENTS, also room for DFSPH's gradient of each entry),
    and the box `obstacles` ([{"min": [...], "max": [...]}], a scene's domain.obstacles) in obstacle_box.
    A box's face that lies on a wall is no face: the box is continued through the wall by the tank's
    size (a box on the floor reaches below it), so that no particle slides between the two on the
    wall, and none inside the box is put back out through the wall (integrate.comp)."""
    state = {}
    for name, (_, c, length) in BUFFERS.items():
        k = buffer_length(length, params, max_neighbours, gradients)
        state[name] = np.zeros((k, c) if c > 1 else k, buffer_dtype(name, precision))
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


def check_obstacles(state, spec):
    """A plan with spec.OBSTACLES boxes reads that many from obstacle_box: each must be a box (min
    below max on every axis used), else the state was made without them (empty_state's
    `obstacles`) and the fluid would flow through them unnoticed."""
    box = np.asarray(state["obstacle_box"])
    for k in range(spec.OBSTACLES):
        if not (box[2 * k, :spec.DIM] < box[2 * k + 1, :spec.DIM]).all():
            raise ValueError(f"the plan has {spec.OBSTACLES} obstacles but obstacle_box[{2 * k}:{2 * k + 2}] = "
                             f"{box[2 * k:2 * k + 2].tolist()} is not a box: pass the scene's domain.obstacles "
                             "to empty_state")


def check_neighbours(state, spec):
    """A plan with neighbour lists (DFSPH, or Scene.spec_for) writes spec.MAX_NEIGHBOURS list slots a
    particle: the state must have room for them (empty_state's `max_neighbours`), and every (j, image)
    must fit in a word (dfsph.glsl)."""
    n, width = len(state["particle_id"]), list_width(spec.MAX_NEIGHBOURS)
    if len(state["neighbours"]) < n * width:
        raise ValueError(f"the plan's neighbour lists need {n} x {width} words but neighbours "
                         f"holds {len(state['neighbours'])}: pass the scene's spec.MAX_NEIGHBOURS to empty_state")
    if spec.GRADIENTS and len(state["neighbour_gradients"]) < n * width:
        raise ValueError(f"DFSPH's pair gradients need {n} x {width} entries but neighbour_gradients holds "
                         f"{len(state['neighbour_gradients'])}: pass the spec's GRADIENTS to empty_state")
    if spec.MAX_NEIGHBOURS > 0 and (n > NEIGHBOUR_MASK or n * width >= 2 ** 32):
        raise ValueError(f"{n} particles with {spec.MAX_NEIGHBOURS} neighbour slots each: the neighbour lists "
                         f"index at most {NEIGHBOUR_MASK + 1} particles and 2^32 slots in all")


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


def dispatch_size(stage, params):
    """Invocations of `stage`: one per particle, cell, or node of the pyramid level it builds (or one)."""
    kind = STAGES[stage.name][1]
    if kind == "particles":
        return int(params[0]["n"])
    if kind == "one":
        return 1
    cells = int(params[0]["cell_total"])
    if kind == "cells":
        return cells
    for _ in range(stage.level):
        cells = (cells + 7) // 8
    return cells


def stage_params(params, stage):
    """The parameter block pushed for one dispatch of `stage` (its pyramid level filled in)."""
    if stage.level == 0:
        return params
    p = params.copy()
    p[0]["level"] = stage.level
    return p


TRY_EVERY = 20  # numba: every TRY_EVERY-th call of compute_density runs the scan not chosen (Faster)
TIMED_FROM = 4096  # and from this many particles (below, a scan takes well under a millisecond: the second
#                    scan's compiling, about 2 s when the cache is cold, would not pay)


class Faster:
    """Two launches of one stage that write the same bits (compute_density's scans with and without a branch
    on the distance, where it writes lists). The chosen one runs and is timed; every TRY_EVERY-th call the other
    runs instead, and is chosen if it took less time than the least of the chosen's calls since the last try.
    Which is faster changes as a flow loses its lattice. A launch of no work groups (warm_up), and the first
    call, compile both."""

    def __init__(self, *launches):
        self.launches, self.calls, self.chosen, self.least = launches, 0, 0, math.inf

    def __call__(self, n_groups, *args):
        if n_groups == 0 or self.calls == 0:
            for launch in self.launches:
                launch(0, *args)
        if n_groups == 0:
            return
        self.calls += 1
        k = self.chosen if self.calls % TRY_EVERY else 1 - self.chosen
        start = time.perf_counter()
        self.launches[k](n_groups, *args)
        seconds = time.perf_counter() - start
        if k == self.chosen:
            self.least = min(self.least, seconds)
            return
        if seconds < self.least:
            self.chosen = k
        self.least = math.inf


class NumbaBackend:
    """The shaders' numba mirrors on the CPU: work groups in parallel, invocations in order.
    `state` is converted to `precision` (a copy: the caller's arrays are never written)."""

    name = "numba"

    def __init__(self, params, state, stages, spec, local_size=128, precision="float32", profile=None):
        self.params, self.stages, self.spec, self.local_size = params, stages, spec, local_size
        self.profile = profile  # a sphcore.profile.Profile: each launch timed by the host clock
        if profile is not None:
            profile.device = "cpu (numba)"
        self.precision, self.real = precision, buffer_dtype("particle_x", precision).type
        self.state = {k: np.array(state[k], buffer_dtype(k, precision), copy=True) for k in BUFFERS}
        self._launch = [(self._launcher(s.name), self._groups(s), stage_params(params, s),
                         [self.state[k] for k in STAGES[s.name][2]], s.when) for s in stages]

    def _launcher(self, name):
        launch = STAGES[name][0](self.spec, self.real)
        if name == "compute_density" and can_list_first(self.spec) and self.params[0]["n"] >= TIMED_FROM:
            return Faster(launch, compute_density(self.spec._replace(BRANCH_FREE_SCAN=True), self.real))
        return launch

    def _groups(self, stage):
        """A stage's work groups, or for an indirect one the index in control to read them from
        (as a negative number: -1 - index)."""
        if stage.indirect:
            return -1 - indirect_offset(stage)
        return group_count(dispatch_size(stage, self.params), self.local_size)

    def _launch_groups(self, groups, when=ALWAYS):
        """A launch's work groups now: none where the stage's `when` does not hold (reused lists: a build or not,
        as control[CONTROL_REBUILD] says)."""
        if when != ALWAYS and (self.state["control"][CONTROL_REBUILD] != 0) != (when == BUILD):
            return 0
        return groups if groups >= 0 else int(self.state["control"][-1 - groups])

    def warm_up(self, after_each=None):
        """Compile every stage of the plan without running it (a launch of no work groups: numba
        compiles a mirror on its first call), calling `after_each()` after each."""
        for launch, _, params, buffers, _ in self._launch:
            launch(0, self.local_size, params, *buffers)
            if after_each is not None:
                after_each()

    def run_stage(self, stage):
        stage = stage if isinstance(stage, Stage) else Stage(stage)
        launch = STAGES[stage.name][0](self.spec, self.real)
        launch(self._launch_groups(self._groups(stage), stage.when), self.local_size, stage_params(self.params, stage),
               *(self.state[k] for k in STAGES[stage.name][2]))

    def step(self, count=1):
        if self.profile is not None:
            return self._profiled_step(count)
        for _ in range(count):
            for launch, groups, params, buffers, when in self._launch:
                n_groups = self._launch_groups(groups, when)
                if n_groups:  # (a launch of no work groups does nothing: skipped, as numba's call costs)
                    launch(n_groups, self.local_size, params, *buffers)

    def _profiled_step(self, count):
        for _ in range(count):
            for stage, (launch, groups, params, buffers, when) in zip(self.stages, self._launch):
                n_groups = self._launch_groups(groups, when)
                if n_groups:  # (as step: a launch of no work groups is skipped)
                    start = time.perf_counter()
                    launch(n_groups, self.local_size, params, *buffers)
                    self.profile.add(profile_name(stage), time.perf_counter() - start)
        self.profile.steps += count

    def read(self, names=None):
        """Copies of the buffers `names` (default: every buffer)."""
        return {k: self.state[k].copy() for k in (BUFFERS if names is None else names)}

    def read_buffer(self, name):
        """One buffer's contents (a copy)."""
        return self.state[name].copy()

    def write_buffer(self, name, values):
        """Set a buffer's contents."""
        self.state[name][...] = values

    def clear_status(self):
        self.state["grid_status"][:] = STATUS_CLEAR

    def close(self):
        pass


FIRST_WINDOW = 8  # DFSPH on Vulkan: the iterations recorded per window of a solve before any step has run
LEAST_WINDOW = 4  # and the least after that (VulkanBackend.next_window)
WINDOW_LOOKBACK = 32  # the steps whose iterations size the next windows (at most HISTORY_ROWS)


class VulkanBackend:
    """The shaders through Vulkan: device-local buffers, many steps per command buffer. With
    precision "float64" the shaders are built with SPHCORE_FLOAT64 (the device must support
    shaderFloat64, else VulkanError); `state` is converted to `precision`.

    DFSPH, where the device has conditional rendering: each solve's iterations are recorded a window at a
    time (shaders/sph/dfsph.glsl: windows), sized from the iterations the last steps took, rather than
    the whole budget, most of which would be dispatches of no work groups. A solve that spends its
    window unconverged skips the rest of the submission; `step` then records its next window and the
    rest of that step, and goes on: the same updates in the same order as with the whole budget recorded."""

    name = "vulkan"

    def __init__(self, params, state, stages, spec, local_size=128, device=None, validation=None,
                 steps_per_submit=64, precision="float32", before_allocating=None, profile=None):
        """`before_allocating(ctx)`: called once the device is chosen, before any buffer is made
        (sphcore.Simulation checks there that lavapipe's buffers fit in host memory)."""
        from sphcore.vk_runner import Context
        self.dtypes = {name: buffer_dtype(name, precision) for name in BUFFERS}
        self.defines = ("SPHCORE_FLOAT64",) if precision == "float64" else ()
        self.ctx = Context(device=device, validation=validation, float64=precision == "float64")
        if before_allocating is not None:
            before_allocating(self.ctx)
        self.params, self.stages, self.steps_per_submit, self.precision = params, stages, steps_per_submit, precision
        if any(s.when != ALWAYS for s in stages) and not self.ctx.conditional_rendering:
            from sphcore.vk_runner import VulkanError
            name = self.ctx.device_name
            self.ctx.close()
            raise VulkanError(f"{name} has no VK_EXT_conditional_rendering, which reused neighbour lists "
                              "(physics.list_skin) need to skip the sort between builds: set physics.list_skin = 0, "
                              "or run on the numba backend")
        self.profile = profile  # a sphcore.profile.Profile: a GPU timestamp after every dispatch of step()
        if profile is not None:
            profile.device = self.ctx.device_name
            self.ctx.timer(1).free()  # a device without timestamps says so now (VulkanError)
        self.shapes = {}
        self.buffers = {}
        for name in BUFFERS:
            self.shapes[name] = np.shape(state[name])
            self.buffers[name] = self.ctx.buffer(int(np.prod(self.shapes[name])) * self.dtypes[name].itemsize, name)
            self.buffers[name].write(np.asarray(state[name], self.dtypes[name]))
        self.local_size, self.spec_values = local_size, spec.values()
        self.pipelines = {}
        for name in sorted({s.name for s in stages}):
            self._pipeline(name)
        self._recordings = {}
        self._known = {}  # name -> a copy of a small buffer as the device holds it, until the device runs again
        # DFSPH: each solve's budget (its recorded iterations in the plan) and window
        self.budget = {solve: sum(s.indirect and s.level == solve for s in stages) // 2
                       for solve in (SOLVE_DIVERGENCE, SOLVE_DENSITY)}
        self.windows, self.resumptions = None, 0  # (resumptions: submissions that went on from a spent window)
        if spec.DFSPH and self.ctx.conditional_rendering and self.budget[SOLVE_DENSITY] > 0:
            self.windows = {solve: min(FIRST_WINDOW, budget) for solve, budget in self.budget.items()}

    def _pipeline(self, name):
        """The compute pipeline of shader `name`, built on first use with the scene's constants."""
        from sphcore.vk_runner import compile_glsl
        if name not in self.pipelines:
            spirv = compile_glsl(SHADER_DIR / "sph" / f"{name}.comp", defines=self.defines)
            pipeline = self.ctx.pipeline(spirv, len(BUFFERS), self.params.dtype.itemsize, self.local_size,
                                         self.spec_values)
            pipeline.bind([self.buffers[b] for b in BUFFERS])
            self.pipelines[name] = pipeline
        return self.pipelines[name]

    def _recording(self, steps, stages, timed=False, predicate=False, secondary=False):
        """`steps` steps of `stages` in one command buffer (`secondary`: a secondary one); `timed`: a
        timestamp after each dispatch; `predicate`: each dispatch only while control[CONTROL_RUNNING]
        is not 0. Untimed, the steps run one step's secondary command buffer (recorded once: a dispatch
        costs about 30 us of Python to record)."""
        key = (steps, tuple(stages), timed, predicate, secondary)
        if key not in self._recordings:
            rec = self.ctx.record(secondary)
            rec.stages = stages * steps
            rec.timer = self.ctx.timer(len(rec.stages) + 1) if timed else None
            if steps > 1 and not timed:
                rec.execute([self._recording(1, stages, predicate=predicate, secondary=True)] * steps)
                self._recordings[key] = rec.end()
                return rec
            control = self.buffers["control"]
            running = (control, 4 * CONTROL_RUNNING) if predicate else None
            if timed:
                rec.timestamp(rec.timer, 0)
            # reused lists: a run of BUILD (or REUSE) stages is one block of conditional rendering (with a predicate
            # per dispatch the H200 took 0.630 instead of 0.600 ms a step at 1 M particles and a skin of 0.1 h)
            when = lambda w: None if w == ALWAYS else (control, 4 * CONTROL_REBUILD, w == REUSE)  # noqa: E731
            block = ALWAYS
            for k, stage in enumerate(rec.stages):
                if stage.when != block:
                    rec.end_conditional(when(block))
                    rec.begin_conditional(when(stage.when))
                    block = stage.when
                if stage.indirect:
                    rec.dispatch_indirect(self.pipelines[stage.name], stage_params(self.params, stage), control,
                                          4 * indirect_offset(stage), predicate=running)
                else:
                    rec.dispatch(self.pipelines[stage.name], stage_params(self.params, stage),
                                 dispatch_size(stage, self.params), predicate=running if block == ALWAYS else None)
                # a barrier for the commands too where the next stage (of the step, or of the next step) reads
                # control as one: an indirect dispatch, a block of conditional rendering, or every dispatch
                after = rec.stages[(k + 1) % len(rec.stages)]
                rec.barrier(predicate or after.indirect or after.when not in (ALWAYS, stage.when))
                if timed:
                    rec.timestamp(rec.timer, 1 + k)
            rec.end_conditional(when(block))
            self._recordings[key] = rec.end()
        return self._recordings[key]

    def _submit(self, rec):
        self._known.clear()
        self.ctx.submit(rec)
        if rec.timer is not None:
            for stage, seconds in zip(rec.stages, rec.timer.seconds()):
                self.profile.add(profile_name(stage), seconds)

    def _submit_steps(self, steps):
        self._submit(self._recording(steps, self.stages, timed=self.profile is not None))
        if self.profile is not None:
            self.profile.steps += steps

    def _windowed(self, stages):
        """`stages` with each run of a solve's indirect stages cut to its window's iterations."""
        out, run = [], 0
        for stage in stages:
            run = run + 1 if stage.indirect else 0
            if not stage.indirect or run <= 2 * self.windows[stage.level]:
                out.append(stage)
        return out

    def _resumed(self, solve):
        """What a step suspended at the end of a window of `solve` has left: the solve's next window, then
        the stages after it (windowed)."""
        last = max(k for k, s in enumerate(self.stages) if s.indirect and s.level == solve)
        return self._windowed(dfsph_solve(solve, self.windows[solve])[1:] + self.stages[last + 1:])

    def _windowed_steps(self, steps, control):
        """Run up to `steps` steps with windows (dfsph.glsl) from the device's control as `control` holds
        it, resuming a suspended solve to the end of its step (the submission's later steps were skipped);
        return (the control after them, the steps completed)."""
        first, timed = int(control[CONTROL_STEP]), self.profile is not None
        stages = self._windowed(self.stages)
        while True:
            control[CONTROL_RUNNING] = 1
            for solve, window in self.windows.items():
                control[CONTROL_WINDOW + solve] = window
            if not np.array_equal(control, self._known.get("control")):  # (mostly the device's already)
                self.write_buffer("control", control)
            self._submit(self._recording(steps, stages, timed, predicate=True))
            control = self._read("control")
            if control[CONTROL_RUNNING]:
                break
            # a solve spent its window unconverged, the rest of the submission was skipped: resume there
            solve = SOLVE_DIVERGENCE if not control[CONTROL_DONE + SOLVE_DIVERGENCE] else SOLVE_DENSITY
            stages, steps = self._resumed(solve), 1
            self.resumptions += 1
        last = int(control[CONTROL_STEP])
        if timed:
            self.profile.steps += last - first
        # the next windows, from the iterations the last WINDOW_LOOKBACK steps took
        if last > first:
            history = self._read("dfsph_history")
            rows = history[[(step - 1) % HISTORY_ROWS for step in range(max(0, last - WINDOW_LOOKBACK) + 1, last + 1)]]
            for solve, column in ((SOLVE_DIVERGENCE, 3), (SOLVE_DENSITY, 5)):
                self.windows[solve] = self.next_window(int(rows[:, column].max()), self.budget[solve])
        return control, last - first

    @staticmethod
    def next_window(most, budget):
        """A solve's next window, from the most iterations it took in the last WINDOW_LOOKBACK steps: the least
        power of two (few distinct recordings) above most + 1, at least LEAST_WINDOW, within its budget. A
        window too short costs a resumption (a round trip to the host, about a millisecond), one too long
        two empty dispatches per iteration (a few microseconds; measured on the H200 by
        benchmarks/dfsph_windows.py, benchmarks/results/dfsph/h200/windows_*.json)."""
        return min(budget, max(LEAST_WINDOW, 1 << (most + 1).bit_length()))

    def run_stage(self, stage):
        stage = stage if isinstance(stage, Stage) else Stage(stage)
        self._pipeline(stage.name)
        self._submit(self._recording(1, [stage]))

    def step(self, count=1):
        if self.windows is None:
            full, rest = divmod(count, self.steps_per_submit)
            for _ in range(full):
                self._submit_steps(self.steps_per_submit)
            if rest:
                self._submit_steps(rest)
            return
        control, done = self._read("control"), 0
        while done < count:
            steps = min(count - done, self.steps_per_submit)
            control, steps = self._windowed_steps(steps, control)
            done += steps

    def _read(self, name):
        """A buffer's contents as the device holds them (a small one read once between the device's runs)."""
        if name not in self._known:
            array = self.buffers[name].read(self.dtypes[name], self.shapes[name])
            if array.nbytes > STAGING_KEPT:
                return array
            self._known[name] = array
        return self._known[name].copy()

    def read(self, names=None):
        """The buffers `names` (default: every buffer), read back from the device."""
        return {name: self.read_buffer(name) for name in (BUFFERS if names is None else names)}

    def read_buffer(self, name):
        """One buffer's contents, read back from the device. control as the mirror keeps it: the windows
        the Vulkan host leaves on the device between calls (dfsph.glsl) read as 0."""
        array = self._read(name)
        if name == "control":
            array[CONTROL_WINDOW + SOLVE_DIVERGENCE] = array[CONTROL_WINDOW + SOLVE_DENSITY] = 0
        return array

    def write_buffer(self, name, values):
        """Set a buffer's contents on the device."""
        array = np.asarray(values, self.dtypes[name]).reshape(self.shapes[name])
        self.buffers[name].write(array)
        self._known.pop(name, None)
        if array.nbytes <= STAGING_KEPT:
            self._known[name] = array.copy()

    def clear_status(self):
        self.write_buffer("grid_status", STATUS_CLEAR)

    def close(self):
        if self.ctx.device is None:
            return
        self.ctx.vk.vkDeviceWaitIdle(self.ctx.device)
        for rec in self._recordings.values():
            rec.free()
            if rec.timer is not None:
                rec.timer.free()
        for p in self.pipelines.values():
            p.free()
        for b in self.buffers.values():
            b.free()
        self.ctx.close()


BACKENDS = {"numba": NumbaBackend, "vulkan": VulkanBackend}


MAX_LOCAL_SIZE = 1024  # invocations of a work group: the most any Vulkan device allows (maxComputeWorkGroupInvocations)


def check_options(name, options):
    """Refuse (ValueError, one line) an unknown backend, an option backend `name` does not take, or a
    local_size that is no integer within [1, MAX_LOCAL_SIZE]: before a run deletes or writes anything.
    Any size in that range works on both backends (the reductions, choose_dt and reduce_dt, handle a
    group that is not a power of two)."""
    if name not in BACKENDS:
        raise ValueError(f"unknown backend {name!r}: choose one of {', '.join(BACKENDS)}")
    import inspect

    taken = [k for k in inspect.signature(BACKENDS[name].__init__).parameters
             if k not in ("self", "params", "state", "stages", "spec")]
    unknown = sorted(set(options) - set(taken))
    if unknown:
        raise ValueError(f"the {name} backend takes no option {unknown[0]!r} (its options: {', '.join(taken)})")
    local_size = options.get("local_size", 128)
    if isinstance(local_size, bool) or not isinstance(local_size, (int, np.integer)) \
            or not 1 <= local_size <= MAX_LOCAL_SIZE:
        raise ValueError(f"local_size must be an integer within [1, {MAX_LOCAL_SIZE}] (a work group's invocations), "
                         f"got {local_size!r}")


def make_backend(name, params, state, stages, spec, **options):
    """Backend `name` over `state`; options: local_size, precision ("float32" | "float64"), and
    for Vulkan device, validation, steps_per_submit."""
    check_options(name, options)
    check_obstacles(state, spec)
    check_neighbours(state, spec)
    return BACKENDS[name](params, state, stages, spec, **options)
