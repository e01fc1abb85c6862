"""The two ways to run the shaders: their numba mirrors (default) and Vulkan.

Both execute the same plan, an ordered list of stages (sphcore.plan: `plan`), over the same buffers
bound at the same binding numbers (`BUFFERS`), with the same parameter bytes and the same
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

import numpy as np

from sphcore.params import DISPATCH_DTYPE, PARAMS_BINDING, SHADER_DIR, UNIFORM_BYTES
from sphcore.plan import BUFFERS, STAGES, STATUS_CLEAR, buffer_dtype, row_bytes
from sphcore.plan import (PARTICLE_BUFFERS, PRECISIONS, REAL, buffer_length, empty_state,  # noqa: F401 (the plan
                          in_particle_order, list_entries, neighbour_stages, plan)  # and buffers' old paths)
from sphcore.solvers.dfsph import dfsph_solve
from sphcore.sph.compute_density import can_list_first, compute_density
from sphcore.sph.dfsph import (CONTROL_DONE, CONTROL_REBUILD, CONTROL_RUNNING, CONTROL_STEP, CONTROL_WINDOW,
                               HISTORY_ROWS, NEIGHBOUR_MASK, SOLVE_DENSITY, SOLVE_DIVERGENCE, dispatch_base, list_width)
from sphcore.stage import ALWAYS, BUILD, REUSE, Stage
from sphcore.vk_runner import Context, VulkanError, compile_glsl
from sphcore.vk_runner.context import STAGING_KEPT
from sphcore.workgroups import group_count

NAMES = list(BUFFERS)  # binding number = index
SIZED = ("particles", "neighbours", "gradients")  # BUFFERS' lengths that follow the particle count
HEADROOM = 1.25  # a load past a backend's capacity grows its buffers to this many times the count
# Vulkan: the small buffers the host writes and reads every step of a rank's exchange (sphcore.parallel.Rank), and
# dt_partial, whose first row it reads and writes (Rank.reduce_dt), in memory the host maps where the device has it
# (host-visible device memory: no submission to write or read them)
MAPPED = ("pick_table", "pick_bounds", "pick_count", "control", "layer_start", "place_table", "dt_partial",
          "rank_groups")
# read_regions packs each region from a multiple of PACK_GRAIN bytes: an H100 copied 40 runs of 1.1 MB in 194 us where
# each run's bytes were a multiple of 16, in 520 us where they were one of 4 (benchmarks/copy_regions.py)
PACK_GRAIN = 16


def packed(nbytes):
    """`nbytes` (an int or an integer array) rounded up to a multiple of PACK_GRAIN: a region's room in a pack."""
    return -(-nbytes // PACK_GRAIN) * PACK_GRAIN


def sized_shapes(params, spec):
    """The shape of each buffer whose length follows the particle count (SIZED), for `params`' count."""
    shapes = {}
    for name, (_, c, length) in BUFFERS.items():
        if length in SIZED:
            k = buffer_length(length, params, spec.MAX_NEIGHBOURS, spec.GRADIENTS)
            shapes[name] = (k, c) if c > 1 else (k,)
    return shapes


def profile_name(stage):
    """A stage's row in a profile: its name, "compute_density (walk)" for the walk of reused lists."""
    return stage.name + (" (walk)" if stage.when == REUSE else "")


# A rank's indirect stages (sphcore.parallel) and the row of rank_groups with their (x, y, z) work group counts: the
# pick's rows (pick_groups.comp writes them) and the received rows (the host writes them).
RANK_GROUPS = {"compute_forces": 0, "pick_rows": 0, "pack_rows": 0, "place_rows": 1}


def indirect_source(stage):
    """Where an indirect stage's (x, y, z) work group counts are: (buffer, index of the first): a rank's in
    rank_groups (RANK_GROUPS), a DFSPH solve's in control (dfsph.glsl)."""
    if stage.name in RANK_GROUPS:
        return "rank_groups", 4 * RANK_GROUPS[stage.name]
    return "control", dispatch_base(stage.level)


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


def dispatch_size(stage, params, gauges=1, rows=None, cells=None):
    """Invocations of `stage`: one per particle (or per row of buffers with room for `rows`: the shaders stop
    at P.n), cell of the grid's range (cell_range; or as many as `cells`, a room for ranges: the shaders stop at
    its end), or node of the pyramid level it builds over it (or one, or one per gauge of the `gauges`)."""
    kind = STAGES[stage.name][1]
    if kind == "particles":
        return int(params[0]["n"]) if rows is None else rows
    if kind == "one":
        return 1
    if kind == "gauges":
        return gauges
    first, end = cell_range(params)
    if kind == "cells":
        return end - first if cells is None else cells
    if cells is None:  # (the nodes over the range, as reduce_cells.comp takes them)
        return ((end - 1) >> (3 * stage.level)) - (first >> (3 * stage.level)) + 1
    for _ in range(stage.level):  # (a range of that many cells from any cell spans one node more at most)
        cells = (cells + 7) // 8
    return cells + 1


def cell_range(params):
    """The cells the grid's cell stages take (grid_range.glsl): a rank's range, else every cell."""
    P = params[0]
    return (int(P["cells_first"]), int(P["cells_end"])) if P["cells_end"] > 0 else (0, int(P["cell_total"]))


def stage_params(params, stage):
    """The parameter record of one dispatch of `stage` for the numba mirrors: the block with the dispatch's
    fields (params.glsl: Dispatch, the level) filled in."""
    if stage.level == 0:
        return params
    p = params.copy()
    p[0]["level"] = stage.level
    return p


def stage_dispatch(stage):
    """The push constants of one dispatch of `stage` on Vulkan (params.glsl: Dispatch)."""
    dispatch = np.zeros(1, DISPATCH_DTYPE)
    dispatch[0]["level"] = stage.level
    return dispatch


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
        self.gauges = len(self.state["gauge_state"]) // 2
        self.store = {}  # (load: each SIZED buffer's whole array, of which state holds the first rows)
        self._launches()

    def _launches(self):
        self._launch = [(self._launcher(s.name), self._groups(s), stage_params(self.params, s),
                         [self.state[k] for k in STAGES[s.name][2]], s.when) for s in self.stages]

    def resize(self, params, ahead=False):
        """Hold `params`' count of particles in place: each SIZED buffer is a view of the first rows of an array
        as long as the most particles held so far (grown to HEADROOM times the count where the count exceeds
        it, its rows copied); the rows up to the old count keep their values. The mirrors see arrays of the count.
        (`ahead`: Vulkan's.)"""
        for name, shape in sized_shapes(params, self.spec).items():
            whole = self.store.get(name, self.state[name])
            if len(whole) < shape[0]:
                grown = np.zeros((int(shape[0] * HEADROOM), *shape[1:]), whole.dtype)
                grown[:len(self.state[name])] = self.state[name]
                whole = grown
            self.store[name] = whole
            self.state[name] = whole[:shape[0]]
        self.params = params
        self._launches()

    def load(self, params, particles, kept=()):
        """Hold another particle set, of `params`' count, in place (sphcore.stepper.Simulation.load; resize):
        `particles` maps buffer names to its values; the buffers in `kept` stay as they are, every other one is
        zeroed."""
        self.resize(params)
        for name in BUFFERS:
            if name in particles:
                self.state[name][...] = particles[name]
            elif name not in kept:
                self.state[name][...] = 0

    def read_rows(self, name, start, stop):
        """Rows start .. stop - 1 of a buffer (a copy)."""
        return self.state[name][start:stop].copy()

    read_mapped = read_rows  # (Vulkan's: no submission is left running here)

    def write_rows(self, name, start, values):
        """Set a buffer's rows from `start` on to `values`."""
        self.state[name][start:start + len(values)] = values

    write_mapped = write_rows  # (Vulkan's: no submission is left running here)

    def read_regions(self, regions, into=None):
        """The bytes of rows start .. stop - 1 of buffer `name`, for each (name, start, stop) of `regions`, one
        region's after the other's, each from a multiple of PACK_GRAIN bytes (one uint8 array; from the start of
        `into`, host_buffer's, where given)."""
        parts = [self.state[name][start:stop].view(np.uint8).reshape(-1) for name, start, stop in regions]
        out = np.zeros(sum(packed(len(part)) for part in parts), np.uint8) if into is None else into
        at = 0
        for part in parts:
            out[at:at + len(part)] = part
            at += packed(len(part))
        return out if into is None else None

    def bind_words(self, name, data):
        """`data` (uint8: bytes) as buffer `name`'s words ("received", "sent")."""
        self.state[name] = data.view(np.uint32)

    def host_buffer(self, memory):
        """`memory` (uint8) as read_regions' `into` and write_regions' `data`: itself."""
        return memory

    def space_to_write(self, nbytes):
        """An array of `nbytes` (uint8) to fill with write_regions' `data`."""
        return np.empty(nbytes, np.uint8)

    def write_regions(self, data, regions):
        """Set rows of buffers to bytes of `data` (uint8): for each (name, row, offset, count) of `regions`,
        `count` rows from `row` on to the bytes from `offset` on."""
        for name, row, offset, count in regions:
            rows = self.state[name][row:row + count]
            rows.view(np.uint8).reshape(-1)[...] = data[offset:offset + rows.nbytes]

    def write_parts(self, parts, move=None):
        """write_regions of each (data, regions) of `parts`, after move_rows(*move) where given (rows the writes do
        not touch)."""
        if move is not None:
            self.move_rows(*move)
        for data, regions in parts:
            self.write_regions(data, regions)

    def move_rows(self, source, destination, count):
        """Copy rows source .. source + count - 1 of every per-particle buffer to rows destination .. (the two
        runs must not overlap)."""
        for name in sized_shapes(self.params, self.spec):  # (past the count too: the rows held before a resize)
            if BUFFERS[name][2] == "particles":
                whole = self.store.get(name, self.state[name])
                whole[destination:destination + count] = whole[source:source + count]

    def _launcher(self, name):
        launch = STAGES[name][0](self.spec, self.real)
        if name == "compute_density" and can_list_first(self.spec) and self.params[0]["n"] >= TIMED_FROM:
            return Faster(launch, compute_density(self.spec._replace(BRANCH_FREE_SCAN=True), self.real))
        return launch

    def _groups(self, stage):
        """A stage's work groups, or for an indirect one where to read them from (indirect_source)."""
        if stage.indirect:
            return indirect_source(stage)
        return group_count(dispatch_size(stage, self.params, self.gauges), self.local_size)

    def _launch_groups(self, groups, when=ALWAYS):
        """A launch's work groups now: none where the stage's `when` does not hold (reused lists: a build or not,
        as control[CONTROL_REBUILD] says)."""
        if when != ALWAYS and (self.state["control"][CONTROL_REBUILD] != 0) != (when == BUILD):
            return 0
        if isinstance(groups, tuple):
            name, index = groups
            return int(self.state[name].reshape(-1)[index])
        return groups

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
        launch(self._launch_groups(self._groups(stage), stage.when), self.local_size,
               stage_params(self.params, stage), *(self.state[k] for k in STAGES[stage.name][2]))

    def settle(self, keep=0):
        """(Vulkan's: wait for the submissions left running; here none is.)"""

    def run_stages(self, stages, writes=None, wait=True):
        """`stages` in order, as run_stage runs each; with `writes` ((parts, move): write_parts') first. (`wait`:
        Vulkan's; here every call is done when it returns.)"""
        if writes is not None:
            self.write_parts(*writes)
        for stage in stages:
            self.run_stage(stage)

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
        self.dtypes = {name: buffer_dtype(name, precision) for name in BUFFERS}
        self.row_bytes = {name: row_bytes(name, precision) for name in BUFFERS}
        self.defines = ("SPHCORE_FLOAT64",) if precision == "float64" else ()
        self.ctx = Context(device=device, validation=validation, float64=precision == "float64")
        if before_allocating is not None:
            before_allocating(self.ctx)
        self.params, self.stages, self.steps_per_submit, self.precision = params, stages, steps_per_submit, precision
        if any(s.when != ALWAYS for s in stages) and not self.ctx.conditional_rendering:
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
        self.gauges = len(state["gauge_state"]) // 2
        for name in BUFFERS:
            self.shapes[name] = np.shape(state[name])
            self.buffers[name] = self.ctx.buffer(int(np.prod(self.shapes[name])) * self.dtypes[name].itemsize, name,
                                                 mapped=name in MAPPED)
            self.buffers[name].write(np.asarray(state[name], self.dtypes[name]))
        self.params_buffer = self.ctx.buffer(UNIFORM_BYTES, "params", uniform=True)  # (params.glsl: Params)
        self.params_buffer.write(params.view(np.uint8)[:UNIFORM_BYTES])
        self.params_next = self._params_copy = None  # (resize's with `ahead`: made at the first)
        self.local_size, self.spec, self.spec_values = local_size, spec, spec.values()
        self.pipelines = {}
        self.words = {}  # (bind_words' buffers, bound in place of "received" and "sent")
        for name in sorted({s.name for s in stages}):
            self._pipeline(name)
        self._recordings = {}
        self.cells = self._cell_room(params)  # (the cells a recording dispatches for a cell stage: resize)
        self._known = {}  # name -> a copy of a small buffer as the device holds it, until the device runs again
        # DFSPH: each solve's budget (its recorded iterations in the plan) and window
        self.budget = {solve: sum(s.indirect and s.level == solve for s in stages) // 2
                       for solve in (SOLVE_DIVERGENCE, SOLVE_DENSITY)}
        self.windows, self.resumptions = None, 0  # (resumptions: submissions that went on from a spent window)
        if spec.DFSPH and self.ctx.conditional_rendering and self.budget[SOLVE_DENSITY] > 0:
            self.windows = {solve: min(FIRST_WINDOW, budget) for solve, budget in self.budget.items()}

    def _pipeline(self, name):
        """The compute pipeline of shader `name`, built on first use with the scene's constants."""
        if name not in self.pipelines:
            spirv = compile_glsl(SHADER_DIR / "sph" / f"{name}.comp", defines=self.defines)
            bound = self._bound(name)
            pipeline = self.ctx.pipeline(spirv, list(bound), DISPATCH_DTYPE.itemsize, self.local_size,
                                         self.spec_values, uniform_binding=PARAMS_BINDING)
            pipeline.bind(bound, uniform=self.params_buffer)
            self.pipelines[name] = pipeline
        return self.pipelines[name]

    def _bound(self, name):
        """Stage `name`'s own buffers only, each at its index in BUFFERS (sparse: lavapipe allows 32 a stage);
        bind_words' buffers in place of theirs."""
        return {NAMES.index(b): self.words.get(b) or self.buffers[b] for b in STAGES[name][2]}

    def bind_words(self, name, buffer):
        """Bind `buffer` (a Buffer of this device: sphcore.peers' inbox or outbox; None: the backend's own) in place
        of buffer `name` ("received", "sent"); the recordings that use it go (a recorded dispatch uses the descriptor
        set as it was)."""
        if buffer is not self.words.get(name):
            self.words[name] = buffer
            stages = [stage for stage in self.pipelines if name in STAGES[stage][2]]
            for stage in stages:
                self.pipelines[stage].bind(self._bound(stage), uniform=self.params_buffer)
            if stages:
                self._free_recordings()

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
                    name, index = indirect_source(stage)
                    rec.dispatch_indirect(self.pipelines[stage.name], stage_dispatch(stage), self.buffers[name],
                                          4 * index, predicate=running)
                else:
                    rec.dispatch(self.pipelines[stage.name], stage_dispatch(stage),
                                 dispatch_size(stage, self.params, self.gauges, self.rows, self.cells),
                                 predicate=running if block == ALWAYS else None)
                # a barrier for the commands too where the next stage (of the step, or of the next step) reads
                # control as one: an indirect dispatch, a block of conditional rendering, or every dispatch
                after = rec.stages[(k + 1) % len(rec.stages)]
                rec.barrier(predicate or after.indirect or after.when not in (ALWAYS, stage.when))
                if timed:
                    rec.timestamp(rec.timer, 1 + k)
            rec.end_conditional(when(block))
            self._recordings[key] = rec.end()
        return self._recordings[key]

    def _submit(self, rec, writes=None, wait=True):
        """Run recording `rec`; with `writes` ((parts, move): write_parts') first, in the same submission; `wait`
        False (no timer): left running (Context.submit; one that writes from host memory is waited for)."""
        self._known.clear()
        wait = wait or rec.timer is not None
        if writes is None:
            self.ctx.submit(rec, wait=wait)
        else:
            self.ctx.write_parts(*self._copied(*writes), then=rec, wait=wait)
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

    def run_stages(self, stages, writes=None, wait=True):
        """`stages` in order, in one submission (recorded once, as a step is); timed stage by stage where there is a
        profile. With `writes` ((parts, move): write_parts'), those first, in the same submission. `wait` False:
        left running while the host goes on (Context.submit: the next call that touches the device's memory waits
        for it)."""
        stages = [s if isinstance(s, Stage) else Stage(s) for s in stages]
        for stage in stages:
            self._pipeline(stage.name)
        self._submit(self._recording(1, stages, timed=self.profile is not None), writes, wait)

    def settle(self, keep=0):
        """Wait for the submissions run_stages left running (wait=False), all but the last `keep` of them."""
        self.ctx.settle(keep)

    def resize(self, params, ahead=False):
        """Hold `params`' count of particles in place: the buffers keep their size while the count fits (the
        shaders stop at P.n), else grow to HEADROOM times the count, their contents copied (the pipelines'
        descriptor sets are rebound to the new ones). The uniform gets the new params; with `ahead`, where no
        buffer grows, in the next submission's first commands (queue_first), behind the submission left running,
        which reads it (a rank of sphcore.parallel queues its next step behind its last). The recordings dispatch
        the buffers' capacity (`rows`) and for a cell stage `cells` (_cell_room: a rank's grid range and room to
        widen), so only a growth, or a range wider than `cells` or far narrower, frees them (the device settled
        first; the next steps record anew: a recording of one step's stages is a few milliseconds of Python)."""
        shapes = sized_shapes(params, self.spec)
        grown = [name for name, shape in shapes.items()
                 if int(np.prod(shape)) * self.dtypes[name].itemsize > self.buffers[name].nbytes]
        first, end = cell_range(params)  # (a range wider than the recordings' cells, or under 1 / 1.6 of them: anew)
        cells = self.cells if end - first <= self.cells <= 1.6 * (end - first) else self._cell_room(params)
        fresh = grown or cells != self.cells  # (the recordings freed: recorded anew)
        if fresh:
            self.ctx.settle()  # (the old buffers are copied: as the device left them; the recordings are freed)
        for name in grown:  # (zeroed first, as numba's: a row a rank writes in part, a halo's, holds no garbage
            old = self.buffers[name]  # that the sort, which leaves some buffers in place, could hand an owned row)
            self.buffers[name] = self.ctx.buffer(int(np.prod(shapes[name]) * HEADROOM) * self.dtypes[name].itemsize,
                                                 name, mapped=name in MAPPED)
            rec = self.ctx.record()
            rec.fill(self.buffers[name])
            self.ctx.submit(rec.end())
            rec.free()
            kept = int(np.prod(self.shapes[name])) * self.dtypes[name].itemsize
            if kept:
                self.ctx._copy(old.buffer, self.buffers[name].buffer, [(0, 0, kept)])
            old.free()
        if grown:
            for name, pipeline in self.pipelines.items():
                pipeline.bind(self._bound(name), uniform=self.params_buffer)
        if fresh:
            self._free_recordings()
        self.shapes.update(shapes)
        self.params, self.cells = params, cells
        block = params.view(np.uint8)[:UNIFORM_BYTES]
        if ahead and not fresh:
            if self._params_copy is None:
                self.params_next = self.ctx.buffer(UNIFORM_BYTES, "params_next", mapped=True)
                self._params_copy = self.ctx.record()
                self._params_copy.after_earlier()
                self._params_copy.copy(self.params_next, self.params_buffer, UNIFORM_BYTES)
                self._params_copy.end()
            self.params_next.write(block, settle=False)
            if self._params_copy not in self.ctx.first:
                self.ctx.queue_first(self._params_copy)
        else:
            self.params_buffer.write(block)
            if self._params_copy is not None:  # (a copy still queued copies these)
                self.params_next.write(block)
        self._known = {}

    @staticmethod
    def _cell_room(params):
        """The cells a recording dispatches for a cell stage of `params`' range (cell_range): HEADROOM times as
        many, so that the range may widen a while (a rank's cuts move a layer a step) before it is recorded anew."""
        first, end = cell_range(params)
        return min(int((end - first) * HEADROOM), int(params[0]["cell_total"]))

    @property
    def rows(self):
        """The particles the buffers hold room for: the count the recordings dispatch."""
        return max(int(self.params[0]["n"]), self.buffers["particle_id"].nbytes // 4)

    def _free_recordings(self):
        for rec in self._recordings.values():
            rec.free()
            if rec.timer is not None:
                rec.timer.free()
        self._recordings, self._known = {}, {}

    def load(self, params, particles, kept=()):
        """Hold another particle set, of `params`' count, in place (sphcore.stepper.Simulation.load; resize):
        `particles` maps buffer names to its values; the buffers in `kept` stay as they are on the device, every
        other one is zeroed there (vkCmdFillBuffer)."""
        self.resize(params)
        zeroed = [name for name in BUFFERS if name not in particles and name not in kept]
        if zeroed:
            rec = self.ctx.record()
            for name in zeroed:
                rec.fill(self.buffers[name])
            self.ctx.submit(rec.end())
            rec.free()
        for name, values in particles.items():
            self.write_buffer(name, values)

    def read_rows(self, name, start, stop):
        """Rows start .. stop - 1 of a buffer, read back from the device."""
        shape = (max(stop - start, 0), *self.shapes[name][1:])
        return self.buffers[name].read(self.dtypes[name], shape, start * self.row_bytes[name])

    def write_mapped(self, name, start, values):
        """Set rows of a buffer the host maps (MAPPED) now: while a submission run_stages left running goes on (one
        that does not read them)."""
        array = np.asarray(values, self.dtypes[name]).reshape(-1, *self.shapes[name][1:])
        self.buffers[name].write(array, start * self.row_bytes[name], settle=False)
        self._known.pop(name, None)

    def read_mapped(self, name, start, stop):
        """Rows start .. stop - 1 of a buffer the host maps (MAPPED), as they are: while a submission run_stages left
        running goes on (wait=False; one that does not write them)."""
        shape = (max(stop - start, 0), *self.shapes[name][1:])
        return self.buffers[name].read(self.dtypes[name], shape, start * self.row_bytes[name], settle=False)

    def write_rows(self, name, start, values):
        """Set a buffer's rows from `start` on to `values`, on the device."""
        array = np.asarray(values, self.dtypes[name]).reshape(-1, *self.shapes[name][1:])
        self.buffers[name].write(array, start * self.row_bytes[name])
        self._known.pop(name, None)

    def read_regions(self, regions, into=None):
        """The bytes of rows start .. stop - 1 of buffer `name`, for each (name, start, stop) of `regions`, one
        region's after the other's, each from a multiple of PACK_GRAIN bytes, in one submission: from the start of
        `into` (host_buffer's) where given, else as a view (uint8) of host memory that the next read_regions
        overwrites (the bytes between regions unset)."""
        copies, at = [], 0
        for name, start, stop in regions:
            size = self.row_bytes[name]
            copies.append((self.buffers[name], start * size, at, (stop - start) * size))
            at += packed((stop - start) * size)
        return self.ctx.read_regions(copies, at, into)

    def host_buffer(self, memory):
        """`memory` (uint8, host memory of this process) as a buffer the device copies into and out of directly
        (read_regions' `into`, write_regions' `data`); None where the device cannot (Context.host_buffer).
        Free it (.free()) before the memory goes."""
        return self.ctx.host_buffer(memory.ctypes.data, memory.nbytes)

    def space_to_write(self, nbytes):
        """Host memory of `nbytes` (uint8) to fill with write_regions' `data`, which then is not copied again."""
        return self.ctx.space_to_write(nbytes)

    def write_regions(self, data, regions):
        """Set rows of buffers to bytes of `data` (uint8, or host_buffer's): for each (name, row, offset, count) of
        `regions`, `count` rows from `row` on to the bytes from `offset` on; in one submission."""
        self.write_parts([(data, regions)])

    def write_parts(self, parts, move=None):
        """write_regions of each (data, regions) of `parts`, in one submission: each `data` host_buffer's, or one
        host array (uint8) for them all; with move_rows(*move) where given (rows the writes do not touch)."""
        self.ctx.write_parts(*self._copied(parts, move))

    def _copied(self, parts, move=None):
        """write_parts' copies, as Context.write_parts takes them: (parts, copies_first)."""
        copied = []
        for data, regions in parts:
            copies = []
            for name, row, offset, count in regions:
                size = self.row_bytes[name]
                copies.append((self.buffers[name], offset, row * size, count * size))
                self._known.pop(name, None)
            copied.append((data, copies))
        if move:
            self._known = {}
        return copied, self._moves(*move) if move else ()

    def move_rows(self, source, destination, count):
        """Copy rows source .. source + count - 1 of every per-particle buffer to rows destination .. on the
        device (the two runs must not overlap), in one submission."""
        if count > 0:
            self.ctx._copies(self._moves(source, destination, count))
        self._known = {}

    def _moves(self, source, destination, count):
        """move_rows' copies ((src, dst, regions) each: Context._copies')."""
        copies = []
        for name in sized_shapes(self.params, self.spec) if count > 0 else ():
            if BUFFERS[name][2] == "particles":
                buffer, size = self.buffers[name].buffer, self.row_bytes[name]
                copies.append((buffer, buffer, [(source * size, destination * size, count * size)]))
        return copies

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
        self.params_buffer.free()
        if self._params_copy is not None:
            self._params_copy.free()
            self.params_next.free()
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
