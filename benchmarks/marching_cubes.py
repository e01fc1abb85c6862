"""Marching-cubes extraction time against grid size, side by side in one run.

The field: five metaballs (sum of r_k^2 / |x - c_k|^2 at level 1, fixed centres and radii in
the unit cube, scaled to the grid), on seed 2's five grids (35x67x35 .. 163x323x163), 256^3
and 512^3. Contenders, each timed on the same volume:

- sphcore on Vulkan (the GPU): "histopyramid" (classify, reduce, write the indirect dispatch,
  emit: no readback), "histopyramid_readback" (the vertex count read to the host, then a
  direct dispatch: two submits) and "per_cube" (emit_cubes: runs of cubes along z, one atomic per
  subgroup, sphcore.surface.default_cube_run's run length; with --cube-runs, "per_cube_run<k>" for each).
  The volume stays on the device; --repeat extractions are recorded into one command buffer
  (readback: two submits each) and the wall time between submit and fence is divided by them.
- sphcore on numba: the same stages' mirrors, "histopyramid" and "per_cube" (triangle soup),
  and "weld" (the soup into a shared-vertex mesh on the host, as marching_cubes returns).
- scikit-image's measure.marching_cubes (Lewiner, its default) and VTK's vtkFlyingEdges3D
  (normals on; VTK_SMP_BACKEND_IN_USE=STDThread, as many threads as cores), as peers on the CPU.

Every figure is the median of --repeat timed runs after one warm-up run (compiles, pipeline
creation). Output: JSON (--out), and a table on stdout.

    python benchmarks/marching_cubes.py --contenders numba,skimage,vtk --out benchmarks/results/mc_cpu.json
    python benchmarks/marching_cubes.py --contenders vulkan --out benchmarks/results/mc_h200.json
"""
import argparse
import json
import os
import platform
import statistics
import sys
import time
from pathlib import Path

os.environ.setdefault("VTK_SMP_BACKEND_IN_USE", "STDThread")
os.environ.setdefault("OMP_WAIT_POLICY", "passive")

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

SEED2_GRIDS = [(35, 67, 35), (67, 131, 67), (99, 195, 99), (131, 259, 131), (163, 323, 163)]
# seed 2, ms per extraction on a GTX 560: geometry shader (one invocation per cube), HistoPyramid
SEED2_MS = {(35, 67, 35): (0.65, 0.97), (67, 131, 67): (2.21, 1.09), (99, 195, 99): (5.92, 1.54),
            (131, 259, 131): (12.82, 1.89), (163, 323, 163): (22.22, 2.40)}
CENTRES = np.array([[0.30, 0.35, 0.40], [0.65, 0.30, 0.55], [0.50, 0.65, 0.35], [0.35, 0.70, 0.70],
                    [0.70, 0.65, 0.70]])
RADII = np.array([0.10, 0.12, 0.09, 0.11, 0.08])


def metaballs(shape):
    """Five metaballs on a grid of `shape` over the unit cube, float32, level 1."""
    axes = [np.linspace(0.0, 1.0, k, dtype=np.float32) for k in shape]
    field = np.zeros(shape, np.float32)
    for (cx, cy, cz), r in zip(CENTRES, RADII):
        d2 = ((axes[0] - cx) ** 2)[:, None, None] + ((axes[1] - cy) ** 2)[None, :, None] + ((axes[2] - cz) ** 2)[None, None, :]
        field += np.float32(r * r) / (d2 + np.float32(1e-6))
    return field


def median_ms(run, repeat):
    run()  # warm-up
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        run()
        times.append(time.perf_counter() - t)
    return 1e3 * statistics.median(times)


def time_numba(volume, repeat):
    from sphcore.surface import Extractor, weld
    out = {}
    for method in ("histopyramid", "per_cube"):
        with Extractor(volume.shape, method=method) as extractor:
            soup = extractor.extract(volume, 1.0)
            out[method] = median_ms(lambda: extractor.extract(volume, 1.0), repeat)
    out["weld"] = median_ms(lambda: weld(*soup), repeat)
    out["triangles"] = len(soup[2]) // 3
    return out


def time_vulkan(volume, repeat, cube_runs=()):
    """GPU time per extraction with the volume resident on the device (see the module docstring)."""
    from sphcore.surface import Extractor, default_cube_run
    out = {"cube_run": default_cube_run(volume.shape)}
    for method, readback, run in ([("histopyramid", False, None), ("histopyramid", True, None), ("per_cube", False, None)]
                                  + [("per_cube", False, k) for k in cube_runs]):
        with Extractor(volume.shape, backend="vulkan", method=method, cube_run=run) as extractor:
            soup = extractor.extract(volume, 1.0)  # sizes the output for this surface
            device, stages = extractor.device, extractor.stages()
            name = method + ("_readback" if readback else "") + (f"_run{run}" if run else "")
            if readback:
                first = device.record(stages[:-1]).end()

                def run():
                    device.ctx.submit(first)
                    groups = device.read("arguments")[:3]
                    rec = device.ctx.record()
                    rec.dispatch(device._pipeline("emit_vertices"), extractor.params, groups=groups)
                    device.ctx.submit(rec.end())
                    rec.free()

                out[name] = median_ms(run, repeat)
                first.free()
            else:
                rec = device.ctx.record()
                for _ in range(repeat):
                    if method == "per_cube":
                        rec.fill(device.buffers["arguments"], 0)
                    device.record(stages, rec)
                rec.end()
                out[name] = median_ms(lambda: device.ctx.submit(rec), 3) / repeat
                rec.free()
            out["device"] = device.ctx.device_name
    out["triangles"] = len(soup[2]) // 3
    return out


def time_skimage(volume, repeat):
    from skimage import measure
    return {"lewiner": median_ms(lambda: measure.marching_cubes(volume, 1.0), repeat)}


def time_vtk(volume, repeat):
    import vtk
    from vtk.util import numpy_support
    vtk.vtkSMPTools.Initialize(os.cpu_count())
    image = vtk.vtkImageData()
    image.SetDimensions(volume.shape[2], volume.shape[1], volume.shape[0])  # VTK's x is numpy's last axis
    image.GetPointData().SetScalars(numpy_support.numpy_to_vtk(volume.reshape(-1), deep=True))
    edges = vtk.vtkFlyingEdges3D()
    edges.SetInputData(image)
    edges.SetValue(0, 1.0)
    edges.ComputeNormalsOn()
    edges.ComputeScalarsOff()

    def run():
        edges.Modified()
        edges.Update()

    ms = median_ms(run, repeat)
    return {"flying_edges": ms, "triangles": edges.GetOutput().GetNumberOfCells(),
            "smp_backend": vtk.vtkSMPTools.GetBackend(), "threads": vtk.vtkSMPTools.GetEstimatedNumberOfThreads()}


TIMERS = {"numba": time_numba, "vulkan": time_vulkan, "skimage": time_skimage, "vtk": time_vtk}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--contenders", default="numba,skimage,vtk", help=f"comma list of {', '.join(TIMERS)}")
    parser.add_argument("--sizes", default="seed2,256,512",
                        help="comma list: seed2 (its five grids) or N (an N^3 grid)")
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--cube-runs", default="", help="comma list of emit_cubes run lengths to time beside the "
                        "default (vulkan), e.g. 1,2,4,8: how sphcore.surface.default_cube_run was chosen")
    parser.add_argument("--out", help="JSON file for the results")
    args = parser.parse_args(argv)
    contenders = [c for c in args.contenders.split(",") if c]
    cube_runs = [int(k) for k in args.cube_runs.split(",") if k]
    unknown = set(contenders) - set(TIMERS)
    if unknown:
        parser.error(f"unknown contenders {sorted(unknown)}: choose from {', '.join(TIMERS)}")
    grids = []
    for size in args.sizes.split(","):
        grids += SEED2_GRIDS if size == "seed2" else [(int(size),) * 3]
    results = []
    for shape in grids:
        volume = metaballs(shape)
        row = {"shape": list(shape), "cubes": int(np.prod([k - 1 for k in shape]))}
        if shape in SEED2_MS:
            row["seed2_gtx560_ms"] = dict(zip(("per_cube", "histopyramid"), SEED2_MS[shape]))
        for name in contenders:
            row[name] = TIMERS[name](volume, args.repeat, cube_runs) if name == "vulkan" else TIMERS[name](volume, args.repeat)
            print(f"{'x'.join(map(str, shape)):>12} {name:8} {json.dumps(row[name])}", flush=True)
        results.append(row)
    report = {"benchmark": "marching cubes, five metaballs at level 1", "repeat": args.repeat,
              "machine": {"platform": platform.platform(), "processor": platform.processor(),
                          "cpus": os.cpu_count(), "python": platform.python_version()},
              "results": results}
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(json.dumps(report, indent=1) + "\n")
        print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
