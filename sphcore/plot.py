"""Pictures of a state: particles coloured by speed (3D: seen from the front, along z).

A final.npz is untrusted input: read_final checks it member by member (never unpickling) and says
in one line what is wrong. The picture never replaces a file it did not draw: its --out must be a
.png name, in a folder that exists, and an existing file there must be a PNG `sphcore plot` wrote
(its "Software" text says so). The default, RUN_DIR/final.png, is written through the run folder's
manifest (sphcore.folder), so `--overwrite` knows it as the run's; a picture under another name is
the user's.
"""
import io
import json
import zipfile
import zlib
from pathlib import Path

import numpy as np

from sphcore import folder
from sphcore.errors import SceneError
from sphcore.gauges import FOLDER, read_csv
from sphcore.output import atomic_write_bytes

SOFTWARE = "sphcore plot"  # the PNG's Software text: how plot knows a picture of its own


def _unreadable(path, why):
    return SceneError(f"{path}: not a readable final state ({why})")


def read_final(path):
    """{position, velocity, time, step, scene, config} of final.npz `path` (scene: its name and box;
    config: the whole scene table); SceneError naming the file and what is wrong with it (not an .npz
    archive, damaged, a member missing or of the wrong kind)."""
    path = Path(path)
    try:
        with open(path, "rb") as f:
            magic = f.read(4)
    except OSError as e:
        raise _unreadable(path, e.strerror or e) from None
    if magic not in (b"PK\x03\x04", b"PK\x05\x06"):
        raise _unreadable(path, "not an .npz archive")
    out = {}
    try:
        with np.load(path, allow_pickle=False) as data:
            for name in ("position", "velocity", "time", "scene"):
                if name not in data.files:
                    raise _unreadable(path, f"no member {name!r}")
                try:
                    out[name] = data[name]
                except ValueError as e:
                    if "allow_pickle" in str(e) or "pickle" in str(e):  # never suggest unpickling it
                        raise _unreadable(path, f"member {name!r} holds Python objects, which are never loaded") from None
                    raise
            out["step"] = int(data["step"]) if "step" in data.files and data["step"].shape == () else None
    except SceneError:
        raise
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error) as e:
        raise _unreadable(path, f"a damaged .npz archive: {str(e)[:120]}") from None
    x, v = out["position"], out["velocity"]
    if x.ndim != 2 or x.shape[1] not in (2, 3) or x.dtype.kind != "f" or v.shape != x.shape or v.dtype.kind != "f":
        raise _unreadable(path, f"position {x.dtype}{list(x.shape)} and velocity {v.dtype}{list(v.shape)} are not "
                                "two arrays of N points")
    try:
        scene = out["config"] = json.loads(str(out["scene"]))
        lo, hi = [float(a) for a in scene["domain"]["box_min"]], [float(a) for a in scene["domain"]["box_max"]]
        out["scene"], out["time"] = {"name": str(scene["name"]), "box_min": lo, "box_max": hi}, float(out["time"])
        if not (len(lo) >= 2 and len(hi) >= 2 and hi[0] > lo[0] and hi[1] > lo[1]):
            raise ValueError("an empty box")
    except (ValueError, TypeError, KeyError, IndexError) as e:
        raise _unreadable(path, f"its scene is not a sphcore scene: {str(e)[:80]}") from None
    return out


def is_own_png(path):
    """Whether `path` is a PNG that plot_state drew (its Software text chunk, before the image data)."""
    try:
        with open(path, "rb") as f:
            head = f.read(4096)
    except OSError:
        return False
    return head.startswith(b"\x89PNG\r\n\x1a\n") and f"Software\0{SOFTWARE}".encode() in head


def check_target(out):
    """Refuse a picture path plot must not write: not a .png name, no such folder, or a file it did not draw."""
    out = Path(out)
    if out.suffix.lower() != ".png":
        raise SceneError(f"{out}: not a .png name; `sphcore plot` writes PNG pictures and replaces nothing else")
    if not out.parent.is_dir():
        raise SceneError(f"{out.parent}: no such folder (the folder of --out {out})")
    if out.exists() and not is_own_png(out):
        raise SceneError(f"{out}: exists and is not a picture `sphcore plot` drew; it is never replaced: "
                         "give another --out")


def stale(npz_path, step):
    """The step of checkpoint.npz beside `npz_path` where it is past `step` (the run went on: a resume
    that stopped), else None."""
    checkpoint = Path(npz_path).with_name("checkpoint.npz")
    if step is None or not checkpoint.is_file():
        return None
    try:
        with np.load(checkpoint, allow_pickle=False) as data:
            later = int(data["step"])
    except (OSError, ValueError, KeyError, TypeError, EOFError, zipfile.BadZipFile, zlib.error):
        return None
    return later if later > step else None


def plot_state(npz_path, out=None):
    """Draw final.npz `npz_path` to `out` (default: final.png beside it); return the path written."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    data = read_final(npz_path)
    later = stale(npz_path, data["step"])
    if later is not None:
        raise SceneError(f"{npz_path}: the final state of step {data['step']}, older than checkpoint.npz beside it "
                         f"(step {later}): the run was resumed and stopped before its end; finish it with "
                         f"`sphcore run --resume {Path(npz_path).parent}`")
    out = Path(out or Path(npz_path).with_name("final.png"))
    check_target(out)
    scene = data["scene"]
    lo, hi = scene["box_min"], scene["box_max"]
    x, v = data["position"], data["velocity"]
    fig, ax = plt.subplots(figsize=(7, 7 * (hi[1] - lo[1]) / (hi[0] - lo[0]) + 0.6), dpi=120)
    order = np.argsort(x[:, 2]) if x.shape[1] == 3 else slice(None)  # nearest (largest z) drawn last
    dots = ax.scatter(x[order, 0], x[order, 1], c=np.linalg.norm(v, axis=1)[order], s=4 if x.shape[1] == 2 else 2,
                      cmap="viridis")
    ax.set(xlim=(lo[0], hi[0]), ylim=(lo[1], hi[1]), aspect="equal", xlabel="x [m]", ylabel="y [m]",
           title=f"{scene['name']}: {len(x)} particles, t = {data['time']:.3f} s")
    fig.colorbar(dots, ax=ax, label="speed [m/s]", shrink=0.8)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", bbox_inches="tight", metadata={"Software": SOFTWARE})
    plt.close(fig)
    if out.name == "final.png" and (out.parent / folder.MANIFEST).is_file():  # a run's: in its manifest, locked
        with folder.RunFolder(out.parent) as run_folder:
            run_folder.write_bytes(out.name, buf.getvalue())
    else:
        atomic_write_bytes(out, buf.getvalue())
    return out


def plot_gauges(run_dir):
    """Draw the gauges of the run in `run_dir` (RUN/gauges/*.csv, sphcore.gauges) to RUN/gauges.png, one panel a
    gauge (each component against time); return its path, or None where the run has no gauges. A CSV that is not
    a gauge's is refused in one line (SceneError)."""
    run_dir = Path(run_dir)
    paths = sorted((run_dir / FOLDER).glob("*.csv")) if (run_dir / FOLDER).is_dir() else []
    if not paths:
        return None
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(paths), 1, figsize=(7, 2.2 * len(paths) + 0.4), dpi=120, sharex=True, squeeze=False)
    for ax, path in zip(axes[:, 0], paths):
        try:
            header, rows = read_csv(path)
        except (OSError, ValueError, UnicodeDecodeError) as e:
            plt.close(fig)
            raise SceneError(f"{path}: not a gauge's CSV ({str(e)[:80]})") from None
        if header[0] != "time [s]":
            plt.close(fig)
            raise SceneError(f"{path}: not a gauge's CSV (its first column is {header[0][:40]!r}, not 'time [s]')")
        for k, column in enumerate(header[1:], 1):
            ax.plot(rows[:, 0], rows[:, k], label=column)
        ax.set(title=path.stem, ylabel=header[1].split(" ", 1)[-1] if len(header) > 1 else "")
        ax.legend(loc="best", fontsize="small")
    axes[-1, 0].set_xlabel("time [s]")
    buf = io.BytesIO()
    fig.savefig(buf, format="png", bbox_inches="tight", metadata={"Software": SOFTWARE})
    plt.close(fig)
    out = run_dir / "gauges.png"
    if (run_dir / folder.MANIFEST).is_file():  # a run's: in its manifest, locked
        with folder.RunFolder(run_dir) as run_folder:
            run_folder.write_bytes(out.name, buf.getvalue())
    else:
        check_target(out)
        atomic_write_bytes(out, buf.getvalue())
    return out
