"""NVIDIA Warp's own SPH example beside sphcore, on one GPU, in one process (issue 15's second GPU peer).

The Warp side is `warp/examples/core/example_sph.py` as Warp ships it: its kernels (Mueller et al. 2003:
density, pressure and viscosity over a `wp.HashGrid`, bounds, kick, drift) and its `Example.step`, which
rebuilds the hash grid every step. Only its smoothing length, a constant 0.8 there (62,500 particles), is
chosen here for each particle count: `example(h)` repeats `Example.__init__` with h as a parameter, which sets
n = 32,000 / h^3. Warp's example places its particles one smoothing length apart (a column in a corner of its
box), so each has a few neighbours within h; sphcore's case (`steps_per_second.py --dim 3 --search grid`, as
`peer_taichi_gpu.py` runs it) places them h / 2 apart, about 30 within h. The two cases do different work
per particle, so besides particle-steps per second each row records the mean number of particles within h
(self included, on a sample, from the positions after the timing) and their product, the pairs per second.

sphcore is timed by `steps_per_second.time_case` (64 steps per command buffer), Warp by whole frames of its
example (32 / h steps each), each side for --min-seconds after a warm-up that compiles its kernels. Writes
JSON and a PNG beside it; `--plot FILE.json` draws the PNG from a JSON alone.

Warp's wheel (warp-lang 1.19, 149 MB) is larger than what travels to the GPU machine in one call (64 MiB).
Without its CPU compiler (warp/bin/warp-clang.so: Warp then runs on CUDA devices only), its tests and its
examples' assets, packed as tar.xz, it is 85 MB, which travels in two parts of 42 MB in two calls one after
the other (the machine, still warm, keeps the first part in /tmp). Made here (.warp_a/ and .warp_b/ are
listed in .gitignore, so that only `carry` takes them):

    pip download warp-lang==1.19.0 --python-version 3.12 --only-binary=:all: --no-deps \\
        --platform manylinux_2_28_x86_64 -d /tmp/wd
    pip install --no-deps --target /tmp/w /tmp/wd/warp_lang-1.19.0-*.whl
    rm -r /tmp/w/warp/bin/warp-clang.so /tmp/w/warp/tests /tmp/w/warp/examples/assets
    tar -C /tmp/w -cf - warp | xz -6 -T2 > /tmp/warp.tar.xz
    mkdir .warp_a .warp_b && split -n 2 -d /tmp/warp.tar.xz /tmp/p_
    mv /tmp/p_00 .warp_a/part && mv /tmp/p_01 .warp_b/part

then the first call (carry .warp_a) `mkdir -p /tmp/wparts && cp .warp_a/part /tmp/wparts/part_a`, and the second
(carry .gl, .whl and .warp_b), after the Vulkan preamble of peer_taichi_gpu.py:

    mkdir -p /tmp/warp && cat /tmp/wparts/part_a .warp_b/part | xz -d | tar -x -C /tmp/warp
    PYTHONPATH=/tmp/warp:/tmp/site:. python3 benchmarks/peer_warp_gpu.py --out $OUT/peer_warp_gpu.json
"""
import contextlib
import io
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from benchmarks.peer_taichi_gpu import peer_arguments, peer_record, save, time_sphcore  # noqa: E402
from benchmarks.steps_per_second import make_case  # noqa: E402


def within(x, h, sample=256, seed=0):
    """Mean number of particles within h of a particle (itself included), over `sample` of them."""
    x = np.asarray(x, np.float64)
    pick = np.random.default_rng(seed).choice(len(x), min(sample, len(x)), replace=False)
    return float(np.mean([(((x - x[i]) ** 2).sum(axis=1) < h * h).sum() for i in pick]))


def example(ex, h):
    """Warp's `Example` (module `ex`: warp.examples.core.example_sph) built as its __init__ builds it, with
    smoothing length h instead of its constant 0.8, and no renderer."""
    wp = ex.wp
    e = ex.Example.__new__(ex.Example)
    e.verbose, e.renderer = False, None
    e.frame_dt, e.sim_time = 1.0 / 60, 0.0
    e.smoothing_length = h
    e.width = e.height = e.length = 80.0
    e.isotropic_exp, e.base_density = 20, 1.0
    e.particle_mass = 0.01 * h ** 3
    e.dt = 0.01 * h
    e.dynamic_visc, e.damping_coef, e.gravity = 0.025, -0.95, -0.1
    e.n = int(e.height * (e.width / 4.0) * (e.height / 4.0) / (h ** 3))
    e.sim_step_to_frame_ratio = int(32 / h)
    e.density_normalization = (315.0 * e.particle_mass) / (64.0 * np.pi * h ** 9)
    e.pressure_normalization = -(45.0 * e.particle_mass) / (np.pi * h ** 6)
    e.viscous_normalization = (45.0 * e.dynamic_visc * e.particle_mass) / (np.pi * h ** 6)
    e.x = wp.empty(e.n, dtype=wp.vec3)
    e.v = wp.zeros(e.n, dtype=wp.vec3)
    e.rho = wp.zeros(e.n, dtype=float)
    e.a = wp.zeros(e.n, dtype=wp.vec3)
    wp.launch(kernel=ex.initialize_particles, dim=e.n, inputs=[e.x, h, e.width, e.height, e.length])
    grid_size = int(e.height / (4.0 * h))
    e.grid = wp.HashGrid(grid_size, grid_size, grid_size)
    return e


def run_warp(ex, n, min_seconds):
    """Warp's example at about n particles: particle-steps per second over whole frames, after one frame."""
    wp = ex.wp
    h = (32000.0 / n) ** (1 / 3)
    e = example(ex, h)
    with contextlib.redirect_stdout(io.StringIO()):  # (Example.step prints its ScopedTimer)
        t0 = time.perf_counter()
        e.step()
        wp.synchronize()
        warmup = time.perf_counter() - t0
        frames, start = 0, time.perf_counter()
        while True:
            e.step()
            frames += 1
            wp.synchronize()
            seconds = time.perf_counter() - start
            if seconds >= min_seconds:
                break
    steps = frames * e.sim_step_to_frame_ratio
    x = e.x.numpy()
    return {"n": e.n, "smoothing_length": h, "spacing": h, "steps_per_frame": e.sim_step_to_frame_ratio,
            "steps": steps, "seconds": seconds, "warmup_seconds": warmup, "ms_per_step": 1e3 * seconds / steps,
            "particle_steps_per_second": e.n * steps / seconds, "within_h": within(x, h),
            "finite": bool(np.isfinite(x).all()), "device": str(wp.get_device())}


def plot(record, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = record["rows"]
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(11, 4.2))
    for key, label, mark in (("sphcore_vulkan", "sphcore (Vulkan), h = 2 dx", "o-"),
                             ("warp", "Warp's example_sph (CUDA), h = dx", "s-")):
        n = [r[key]["n"] for r in rows]
        ax.loglog(n, [r[key]["particle_steps_per_second"] for r in rows], mark, label=label)
        bx.loglog(n, [r[key]["pairs_per_second"] for r in rows], mark, label=label)
    ax.set(xlabel="particles", ylabel="particle-steps per second", title=f"one step, {record['device']}")
    bx.set(xlabel="particles", ylabel="particle-steps x particles within h, per second",
           title="the same, times the neighbours")
    ax.legend()
    bx.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    print(f"wrote {path}")


def main():
    args = peer_arguments(__doc__, "benchmarks/results/peer_warp_gpu.json")
    if args.plot:
        return plot(json.loads(args.plot.read_text()), args.plot.with_suffix(".png"))
    try:
        import warp as wp
        from warp.examples.core import example_sph as ex
    except ImportError:
        sys.exit("warp is not importable: pip install warp-lang (see --help)")
    wp.init()

    record = peer_record("peer_warp_gpu", args, warp=wp.config.version)
    print(f"{'N':>9} {'sphcore p-steps/s':>18} {'within h':>8} {'Warp N':>9} {'Warp p-steps/s':>15} {'within h':>8} "
          f"{'ratio':>6} {'pairs ratio':>11}", flush=True)
    for n in args.counts:
        device, mine = time_sphcore(n, args)
        scene, x0 = make_case(n, 3, "grid")
        mine["within_h"] = within(x0, scene.h)  # (the lattice before it moves: the case's own neighbourhood)
        theirs = run_warp(ex, n, args.min_seconds)
        for side in (mine, theirs):
            side["pairs_per_second"] = side["particle_steps_per_second"] * side["within_h"]
        ratio = mine["particle_steps_per_second"] / theirs["particle_steps_per_second"]
        pairs = mine["pairs_per_second"] / theirs["pairs_per_second"]
        record["device"] = device
        record["rows"].append({"n": n, "sphcore_vulkan": mine, "warp": theirs,
                               "ratio_sphcore_over_warp": ratio, "pairs_ratio_sphcore_over_warp": pairs})
        print(f"{n:>9} {mine['particle_steps_per_second']:>18.4g} {mine['within_h']:>8.1f} {theirs['n']:>9} "
              f"{theirs['particle_steps_per_second']:>15.4g} {theirs['within_h']:>8.1f} {ratio:>6.2f} {pairs:>11.2f}"
              f"  ({device}, Warp on {theirs['device']}; finite: {mine['finite']}, {theirs['finite']})", flush=True)
        save(record, args, plot)


if __name__ == "__main__":
    main()
