"""What a resume on several ranks costs each rank's host memory (issue 34): load_checkpoint of a run's checkpoint,
then one rank's share of its rows as Rank.restore takes them, the peak of numpy's allocations (tracemalloc) with
the large members mapped from the file (sphcore.checkpoint.MAPPED_BYTES, the ranks of a host sharing its pages)
and read whole, side by side in one process. Run from the repository root on a run's folder:

    python -m sphcore run scenes/dam_break_3d.toml --steps 1 --out /tmp/big    # (a finer spacing: more particles)
    python benchmarks/checkpoint_memory.py /tmp/big --ranks 2 --out benchmarks/results/checkpoint_memory.json

Prints and appends one JSON line a case to --out.
"""
import argparse
import sys
import time
import tracemalloc
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from steps_per_second import append_line  # noqa: E402

from sphcore import checkpoint, parallel  # noqa: E402
from sphcore.runner import load_checkpoint  # noqa: E402
from sphcore.stepper import LOADED  # noqa: E402

MiB = 2**20


def measure(folder, ranks, mapped):
    """The peak MiB numpy allocated while loading the checkpoint of `folder` and taking rank 0's rows of `ranks`."""
    checkpoint.MAPPED_BYTES = MiB if mapped else 2**62
    tracemalloc.start()
    start = time.perf_counter()
    scene, arrays = load_checkpoint(folder)
    loaded = tracemalloc.get_traced_memory()[1]
    _, keep = parallel.share(scene, ranks, 0, x=arrays["buffer_particle_x"][:, :scene.dim])
    rows = {name: arrays[f"buffer_{name}"][keep] for name in LOADED}
    seconds = time.perf_counter() - start
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return {"mapped": mapped, "ranks": ranks, "particles": len(keep), "held_by_rank_0": int(keep.sum()),
            "checkpoint_mib": round((Path(folder) / checkpoint.CHECKPOINT).stat().st_size / MiB, 1),
            "rows_mib": round(sum(a.nbytes for a in rows.values()) / MiB, 1),
            "peak_loaded_mib": round(loaded / MiB, 1), "peak_mib": round(peak / MiB, 1), "seconds": round(seconds, 2)}


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("folder", help="a run's folder (its checkpoint.npz and scene.json)")
    parser.add_argument("--ranks", type=int, default=2)
    parser.add_argument("--out", type=Path, help="append the JSON lines here")
    args = parser.parse_args()
    for mapped in (False, True):
        append_line(measure(args.folder, args.ranks, mapped), args.out)


if __name__ == "__main__":
    main()
