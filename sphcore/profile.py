"""Per-stage time of the step (`sphcore run --profile`, benchmarks/steps_per_second.py --profile).

Vulkan: a GPU timestamp after every dispatch (vk_runner Timer), so each stage's time is the GPU's
own, with no host in between; a device without timestamps on its compute queue is named, not
profiled. numba: the host clock around each launch (a launch returns when its work is done).

The roofline note beside each stage: the bytes of the buffers it binds, each counted once, against
the H200's 4.8 TB/s. That is what a streaming stage moves if it touches every buffer it binds; a
stage that skips one (a term compiled out) moves less, and one whose data stays in the 50 MB L2 cache
can beat the DRAM figure, so a share above 100 % says the stage is bound by neither. For the two pair
loops: the pair tests they make (every candidate in the 3^dim cells around a particle, wall images
not counted) at an assumed FLOPS_PER_PAIR, against the ~67 TFLOP/s of float32.
"""
import json

import numpy as np

from sphcore.output import atomic_write_bytes
from sphcore.plan import BUFFERS, STAGES, buffer_dtype, buffer_length, plan

H200_BANDWIDTH = 4.8e12  # bytes/s, HBM3e
H200_FP32 = 67e12  # flop/s, float32 without tensor cores
FLOPS_PER_PAIR = 30  # a distance, a compare and (for a neighbour) the kernel and its sums: about 30 flops
PAIR_LOOPS = ("compute_density", "compute_forces")


class Profile:
    """Seconds and dispatches per stage name, summed over `steps` steps; backends add to it."""

    def __init__(self):
        self.seconds, self.calls, self.steps, self.device = {}, {}, 0, None

    def add(self, name, seconds):
        self.seconds[name] = self.seconds.get(name, 0.0) + float(seconds)
        self.calls[name] = self.calls.get(name, 0) + 1

    def rows(self, stage_bytes=None, pairs_per_step=0):
        """One dict per stage, slowest first: ms per step, share of the step, dispatches per step,
        and where `stage_bytes` ({name: bytes per dispatch}) is given, GB/s and % of the H200's
        bandwidth; for the pair loops, pair tests per second and % of its float32 peak."""
        steps = max(self.steps, 1)
        total = sum(self.seconds.values()) or 1.0
        rows = []
        for name, seconds in sorted(self.seconds.items(), key=lambda kv: -kv[1]):
            row = {"stage": name, "ms_per_step": 1e3 * seconds / steps, "share": seconds / total,
                   "dispatches_per_step": self.calls[name] / steps}
            if stage_bytes and name in stage_bytes and seconds > 0:
                rate = stage_bytes[name] * self.calls[name] / seconds
                row.update(bytes_per_dispatch=stage_bytes[name], GB_per_s=rate / 1e9,
                           bandwidth_of_h200=rate / H200_BANDWIDTH)
            if name in PAIR_LOOPS and pairs_per_step and seconds > 0:
                rate = pairs_per_step * steps / seconds
                row.update(pair_tests_per_step=pairs_per_step, pair_tests_per_s=rate,
                           fp32_of_h200=rate * FLOPS_PER_PAIR / H200_FP32)
            rows.append(row)
        return rows

    def table(self, stage_bytes=None, pairs_per_step=0):
        """The rows as text, for a terminal."""
        lines = [f"per-stage profile on {self.device}, {self.steps} steps "
                 f"({1e3 * sum(self.seconds.values()) / max(self.steps, 1):.4g} ms per step in the stages):",
                 f"{'stage':20} {'ms/step':>10} {'share':>7} {'disp/step':>9} {'GB/s':>9} {'of 4.8TB/s':>10} "
                 f"{'pairs/s':>10} {'of 67TF':>8}"]
        for r in self.rows(stage_bytes, pairs_per_step):
            lines.append(f"{r['stage']:20} {r['ms_per_step']:10.4f} {r['share']:7.1%} {r['dispatches_per_step']:9.3g} "
                         + (f"{r['GB_per_s']:9.1f} {r['bandwidth_of_h200']:10.2%}" if "GB_per_s" in r else f"{'':20}")
                         + (f" {r['pair_tests_per_s']:10.3g} {r['fp32_of_h200']:8.2%}" if "pair_tests_per_s" in r else ""))
        return "\n".join(lines)

    def to_json(self, stage_bytes=None, pairs_per_step=0):
        return json.dumps({"device": self.device, "steps": self.steps, "flops_per_pair_assumed": FLOPS_PER_PAIR,
                           "stages": self.rows(stage_bytes, pairs_per_step)}, indent=1)


def stage_bytes(stages, binds, sizes):
    """{stage name: bytes of the buffers it binds} from backends.STAGES' binding lists (`binds`,
    {name: buffer names}) and the buffers' sizes in bytes (`sizes`, {buffer: bytes})."""
    return {s.name: sum(sizes[b] for b in binds[s.name]) for s in stages}


def pair_tests(scene, position):
    """The candidate pairs one pair loop tests with the grid: for each particle, every particle in
    the (2 cell_split + 1)^dim cells around its own (the open domain's cells wrap; wall images not counted)."""
    if scene["physics.neighbour_search"] == "all_pairs":
        return len(position) ** 2
    dims, split = np.array(scene.grid_dim[:scene.dim]), scene.cell_split
    cell = np.floor((np.asarray(position, np.float64) - scene["domain.box_min"]) / scene.cell_size)
    cell = cell.astype(np.int64)
    if scene["domain.boundary"] == "open":
        cell %= dims
    counts = np.zeros(dims)
    np.add.at(counts, tuple(np.clip(cell, 0, dims - 1).T), 1)
    around = np.zeros_like(counts)
    for shift in np.ndindex(*(2 * split + 1,) * scene.dim):
        shifted = counts
        for axis, s in enumerate(shift):
            d = s - split
            shifted = np.roll(shifted, d, axis)
            if scene["domain.boundary"] != "open":  # no wrap at walls: what rolls in from the far side is zeroed
                edge = [slice(None)] * scene.dim
                edge[axis] = slice(0, d) if d >= 0 else slice(d, None)
                shifted = shifted.copy()
                shifted[tuple(edge)] = 0
        around += shifted
    return int((counts * around).sum())


def work(scene, position):
    """({stage: bytes of its buffers}, pair tests per pair loop) of one step of `scene` at `position`."""
    params = scene.params(len(position))
    slots, precision = scene.spec.MAX_NEIGHBOURS, scene["physics.precision"]
    sizes = {name: buffer_length(length, params, slots) * c * buffer_dtype(name, precision).itemsize
             for name, (_, c, length) in BUFFERS.items()}
    return stage_bytes(plan(scene), {name: entry[2] for name, entry in STAGES.items()}, sizes), pair_tests(scene, position)


def report(profile, scene, position, out_dir=None):
    """The profile of a run of `scene` as a table (returned) and, with `out_dir`, out_dir/profile.json;
    the pair tests are counted on `position` (the run's last state)."""
    per_stage, pairs = work(scene, position)
    if out_dir is not None:
        atomic_write_bytes(f"{out_dir}/profile.json", profile.to_json(per_stage, pairs).encode())
    return profile.table(per_stage, pairs)
