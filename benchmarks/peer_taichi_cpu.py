"""Peer benchmark: the same dense 3D weakly compressible SPH step on Taichi's CPU backend and on
sphcore's numba backend, timed one after the other in one process on the same machine.

The case is steps_per_second.py's 3D dam break (make_case(n, 3, "grid")): a cube of n particles
at dx = 0.01 m, h = 2 dx, Tait equation of state, viscosity, gravity, symplectic Euler and
reflecting box walls. Every physical number is read from the scene and its parameter block.
The Taichi side is written here: a uniform grid of cells of size h (the same padded cell size
as sphcore), rebuilt every step by a counting sort that also reorders the particles, then
density, forces and integration, one parallel loop over particles each, 27 cells searched.

    python benchmarks/peer_taichi_cpu.py [--n 64000] [--min-seconds 3] [--threads 2] \
        [--out benchmarks/results/peer_taichi_cpu.json]
"""
import os

os.environ.setdefault("OMP_WAIT_POLICY", "passive")  # before numba is imported: idle threads sleep

import argparse  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from benchmarks.steps_per_second import cpu_name, make_case  # noqa: E402

WARMUP_STEPS = 2  # the first compiles (numba, Taichi JIT); both engines take the same number


def timed(step, sync, min_seconds):
    """Whole chunks of one step until min_seconds have passed: (steps, seconds)."""
    steps, start = 0, time.perf_counter()
    while True:
        step()
        sync()
        steps += 1
        seconds = time.perf_counter() - start
        if seconds >= min_seconds:
            return steps, seconds


def result(n, steps, seconds, warmup, rho, x, v):
    return {"n": n, "steps": steps, "seconds": seconds, "ms_per_step": 1e3 * seconds / steps,
            "particle_steps_per_second": n * steps / seconds, "warmup_seconds": warmup,
            "median_density_after_warmup": float(np.median(rho)),
            "finite": bool(np.isfinite(x).all() and np.isfinite(v).all())}


def run_numba(scene, x0, threads, min_seconds):
    import numba
    from sphcore.backends import empty_state, make_backend, plan
    numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
    n = len(x0)
    params = scene.params(n)
    spec = scene.spec_for("numba")  # (neighbour lists: compute_forces walks compute_density's)
    state = empty_state(params, max_neighbours=spec.MAX_NEIGHBOURS)
    state["particle_x"][:, :3] = x0
    be = make_backend("numba", params, state, plan(scene), spec, local_size=128)
    try:
        t0 = time.perf_counter()
        be.step(WARMUP_STEPS)
        warmup = time.perf_counter() - t0
        rho = be.read()["particle_rho"][:n]
        steps, seconds = timed(lambda: be.step(1), lambda: None, min_seconds)  # step() returns when done
        out = be.read()
    finally:
        be.close()
    row = result(n, steps, seconds, warmup, rho, out["particle_x"][:n, :3], out["particle_v"][:n, :3])
    row["threading_layer"] = numba.threading_layer()
    row["threads"] = numba.get_num_threads()
    return row


def run_taichi(ti, scene, x0, threads, min_seconds, arch=None):
    """The Taichi side on `arch` (default ti.cpu with `threads` threads; peer_taichi_gpu.py: ti.cuda, where
    the cell offsets come from Taichi's parallel PrefixSumExecutor instead of the serial loop)."""
    gpu = arch is not None and arch != ti.cpu
    if gpu:
        ti.init(arch=arch, default_fp=ti.f32, log_level=ti.WARN)
    else:
        ti.init(arch=ti.cpu, cpu_max_num_threads=threads, default_fp=ti.f32, log_level=ti.WARN)
    n = len(x0)
    P = scene.params(n)[0]
    # compile-time constants, all from sphcore's folded parameter block (float32 values)
    h, h2, inv_cell = float(P["h"]), float(P["h2"]), float(P["inv_cell"])
    density_coef, pressure_coef = float(P["density_coef"]), float(P["pressure_coef"])
    viscosity_coef, rho0, B = float(P["viscosity_coef"]), float(P["rest_density"]), float(P["stiffness"])
    dt, e = float(P["dt"]), float(P["restitution"])
    g, lo, hi = [[float(c) for c in P[k]] for k in ("gravity", "box_min", "box_max")]
    gd = [int(c) for c in P["grid_dim"]]  # cells per axis: the box in cells of h * CELL_PADDING
    ncell = gd[0] * gd[1] * gd[2]

    vec = lambda: ti.Vector.field(3, ti.f32, n)  # noqa: E731
    x, v, xs, vs, a = vec(), vec(), vec(), vec(), vec()  # xs, vs: particles in cell order
    rho, p = ti.field(ti.f32, n), ti.field(ti.f32, n)
    cell, slot = ti.field(ti.i32, n), ti.field(ti.i32, n)  # particle's cell, its rank within the cell
    count, start = ti.field(ti.i32, ncell), ti.field(ti.i32, ncell)  # cell i holds xs[start[i]:start[i]+count[i]]

    @ti.func
    def cell_of(q):
        """Integer cell coordinates of q, clamped into the grid (walls keep particles in the box)."""
        c = ti.cast(ti.floor((q - ti.Vector(lo)) * inv_cell), ti.i32)
        return ti.max(ti.min(c, ti.Vector(gd) - 1), 0)

    # counting sort: count per cell, inclusive prefix sum of the counts, scatter
    @ti.kernel
    def bin_particles():
        for c in count:
            count[c] = 0
        for i in x:
            c = cell_of(x[i])
            cell[i] = (c.z * gd[1] + c.y) * gd[0] + c.x
            slot[i] = ti.atomic_add(count[cell[i]], 1)
        for c in count:
            start[c] = count[c]

    @ti.kernel
    def serial_prefix_sum():  # the CPU's: one thread (~26k cells)
        total = 0
        ti.loop_config(serialize=True)
        for c in range(ncell):
            total += start[c]
            start[c] = total

    @ti.kernel
    def scatter_particles():
        for c in start:  # inclusive -> exclusive
            start[c] -= count[c]
        for i in x:
            d = start[cell[i]] + slot[i]
            xs[d] = x[i]
            vs[d] = v[i]

    prefix_sum = ti.algorithms.PrefixSumExecutor(ncell).run if gpu else lambda _: serial_prefix_sum()

    def sort_by_cell():
        bin_particles()
        prefix_sum(start)
        scatter_particles()

    @ti.kernel
    def compute_density():
        for i in xs:
            xi, c, sum_w = xs[i], cell_of(xs[i]), 0.0
            for k in range(27):  # the 3x3x3 cells around i's cell, self included
                nb = c + ti.Vector([k % 3 - 1, k // 3 % 3 - 1, k // 9 - 1])
                if (nb >= 0).all() and (nb < ti.Vector(gd)).all():
                    cid = (nb.z * gd[1] + nb.y) * gd[0] + nb.x
                    for j in range(start[cid], start[cid] + count[cid]):
                        r2 = (xi - xs[j]).norm_sqr()
                        if r2 < h2:
                            q = h2 - r2
                            sum_w += q * q * q  # poly6: rho_i = m 315/(64 pi h^9) sum (h^2 - r^2)^3
            r = density_coef * sum_w
            rho[i] = r
            ratio = r / rho0
            ratio2 = ratio * ratio
            p[i] = ti.max(B * (ratio2 * ratio2 * ratio2 * ratio - 1.0), 0.0)  # Tait, clamped at 0

    @ti.kernel
    def compute_forces():
        for i in xs:
            xi, vi, c = xs[i], vs[i], cell_of(xs[i])
            pi_rho2 = p[i] / (rho[i] * rho[i])
            f_p, f_v = ti.Vector([0.0, 0.0, 0.0]), ti.Vector([0.0, 0.0, 0.0])
            for k in range(27):
                nb = c + ti.Vector([k % 3 - 1, k // 3 % 3 - 1, k // 9 - 1])
                if (nb >= 0).all() and (nb < ti.Vector(gd)).all():
                    cid = (nb.z * gd[1] + nb.y) * gd[0] + nb.x
                    for j in range(start[cid], start[cid] + count[cid]):
                        r = xi - xs[j]
                        r2 = r.norm_sqr()
                        if j != i and r2 < h2:
                            rlen = ti.sqrt(r2)
                            hr = h - rlen
                            # direction j -> i; coincident pair: apart along x, antisymmetric (as sphcore)
                            r_hat = ti.Vector([-1.0 if i < j else 1.0, 0.0, 0.0])
                            if rlen > 0.0:
                                r_hat = r / rlen
                            # pressure, spiky gradient: m 45/(pi h^6) (p_i/rho_i^2 + p_j/rho_j^2) (h - r)^2 r_hat
                            f_p += pressure_coef * (pi_rho2 + p[j] / (rho[j] * rho[j])) * hr * hr * r_hat
                            # viscosity, Mueller et al. 2003: mu m 45/(pi h^6) (h - r) (v_j - v_i) / rho_j
                            f_v += viscosity_coef / rho[j] * hr * (vs[j] - vi)
            a[i] = f_p + f_v / rho[i] + ti.Vector(g)

    @ti.kernel
    def integrate():
        for i in xs:
            vv = vs[i] + dt * a[i]  # symplectic Euler: v += dt a, then x += dt v
            xx = xs[i] + dt * vv
            for d in ti.static(range(3)):  # walls: clamp, reflect outward normal speed times e
                if xx[d] < lo[d]:
                    xx[d] = lo[d]
                    vv[d] = ti.max(vv[d], -e * vv[d])
                if xx[d] > hi[d]:
                    xx[d] = hi[d]
                    vv[d] = ti.min(vv[d], -e * vv[d])
            x[i] = xx  # the next step's input, in this step's cell order
            v[i] = vv

    def step():
        sort_by_cell()
        compute_density()
        compute_forces()
        integrate()

    x.from_numpy(np.ascontiguousarray(x0, np.float32))
    v.fill(0.0)
    t0 = time.perf_counter()
    for _ in range(WARMUP_STEPS):
        step()
    ti.sync()
    warmup = time.perf_counter() - t0
    rho_warm = rho.to_numpy()
    steps, seconds = timed(step, ti.sync, min_seconds)
    assert int(count.to_numpy().sum()) == n  # every particle binned, none dropped (no per-cell cap)
    return result(n, steps, seconds, warmup, rho_warm, x.to_numpy(), v.to_numpy())


def sphcore_revision():
    """HEAD and the files edited since (read-only git), so a figure names the sphcore it timed."""
    import subprocess
    root = Path(__file__).resolve().parent.parent
    try:
        git = lambda *a: subprocess.run(["git", *a], cwd=root, capture_output=True, text=True).stdout  # noqa: E731
        return {"commit": git("rev-parse", "HEAD").strip(), "modified": git("status", "--porcelain").split("\n")[:-1]}
    except OSError as e:
        return {"error": str(e)}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=64000)
    ap.add_argument("--min-seconds", type=float, default=3.0)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--out", type=Path, default=Path("benchmarks/results/peer_taichi_cpu.json"))
    ap.add_argument("--list-skin", type=float, default=0.0,
                    help="also time numba with physics.list_skin = this (its lists reused between builds); Taichi "
                         "keeps its cells of h")
    args = ap.parse_args()
    try:
        import taichi as ti
    except ImportError:
        sys.exit("taichi is not importable: pip install taichi")
    import numba

    loadavg_at_start = os.getloadavg()  # a shared machine: other work skews both engines
    scene, x0 = make_case(args.n, 3, "grid")
    numba_row = run_numba(scene, x0, args.threads, args.min_seconds)
    skin_row = run_numba(make_case(args.n, 3, "grid", list_skin=args.list_skin)[0], x0, args.threads,
                         args.min_seconds) if args.list_skin else None
    taichi_row = run_taichi(ti, scene, x0, args.threads, args.min_seconds)
    ratio = numba_row["particle_steps_per_second"] / taichi_row["particle_steps_per_second"]

    print(f"{'engine':<16} {'particle-steps/s':>16} {'ms/step':>9} {'steps':>6} {'median rho':>10}  finite")
    rows = (("numba", numba_row), (f"numba, skin {args.list_skin:g}", skin_row), ("taichi-cpu", taichi_row))
    for name, row in rows:
        if row is not None:
            print(f"{name:<16} {row['particle_steps_per_second']:>16.4g} {row['ms_per_step']:>9.2f} {row['steps']:>6}"
                  f" {row['median_density_after_warmup']:>10.2f}  {row['finite']}")
    print(f"ratio numba / taichi = {ratio:.3f}  (n = {args.n}, {args.threads} threads, {cpu_name()})")
    if skin_row:
        skin_ratio = skin_row["particle_steps_per_second"] / taichi_row["particle_steps_per_second"]
        print(f"ratio numba with lists reused (physics.list_skin = {args.list_skin:g}) / taichi = {skin_ratio:.3f}")

    record = {"benchmark": "peer_taichi_cpu", "n": args.n, "threads": args.threads, "min_seconds": args.min_seconds,
              "versions": {"python": platform.python_version(), "numpy": np.__version__,
                           "numba": numba.__version__, "taichi": ".".join(map(str, ti.__version__))},
              "cpu_model": cpu_name(), "cpu_count": os.cpu_count(),
              "loadavg_at_start": loadavg_at_start, "loadavg_at_end": os.getloadavg(),
              "env": {k: os.environ.get(k) for k in ("OMP_WAIT_POLICY", "NUMBA_THREADING_LAYER", "NUMBA_NUM_THREADS")},
              "sphcore_git": sphcore_revision(), "scene": scene.config, "warmup_steps": WARMUP_STEPS,
              "numba": numba_row, "taichi": taichi_row,
              "particle_steps_per_second": {"numba": numba_row["particle_steps_per_second"],
                                            "taichi": taichi_row["particle_steps_per_second"]},
              "ratio_numba_over_taichi": ratio,
              "list_skin": args.list_skin, "numba_lists_reused": skin_row,
              "ratio_lists_reused_over_taichi": skin_row and skin_row["particle_steps_per_second"]
              / taichi_row["particle_steps_per_second"],
              "notes": ["Taichi side omits sphcore's mirror-image wall particles (free-slip ghosts): they touch "
                        "only particles within h of a wall; walls are the same clamp-and-reflect in both.",
                        "Taichi: counting sort into a uniform grid of cell size h (sphcore's padded size) every "
                        "step, particles reordered by cell, 27 cells searched, no per-cell cap.",
                        "Taichi runs with its defaults (fast_math on); sphcore's numba mirrors run without fastmath.",
                        "Same process, numba first then Taichi; one step per timed chunk; Taichi ti.sync() before "
                        "each clock read. median_density_after_warmup: a physics sanity check (both near rho0)."]}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(record, indent=2, default=float) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
