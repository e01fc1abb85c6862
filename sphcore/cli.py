"""Command line: `sphcore run SCENE`, `sphcore run --resume RUN_DIR`, `sphcore keys`, `sphcore plot RUN_DIR`,
`sphcore render RUN_DIR`."""
import argparse
import json
import math
import os
import signal
import sys
from pathlib import Path

from sphcore import __version__, folder
from sphcore.errors import CheckpointError, SceneError, ShaderCompileError, SimulationError, VulkanError
from sphcore.paths import SCENE_DIR  # noqa: F401 (tests and scripts import it from here)
from sphcore.scene import SCHEMA, Scene, describe_schema, scene_path  # noqa: F401 (scene_path: tests import it)


def printable(message):
    """`message` with control characters other than newlines escaped (a file name may hold any)."""
    return "".join(c if c.isprintable() or c == "\n" else repr(c)[1:-1] for c in str(message))


def differences(given, stored, source, most=2):
    """'key: x in SOURCE, y in the run' for the first `most` dotted keys whose values differ."""
    found = []

    def walk(a, b, where):
        if isinstance(a, dict) and isinstance(b, dict):
            for name in sorted(set(a) | set(b)):
                walk(a.get(name), b.get(name), f"{where}.{name}" if where else name)
        elif a != b:
            found.append(f"{where}: {json.dumps(a)} in {source}, {json.dumps(b)} in the run")

    walk(given, stored, "")
    more = f" and {len(found) - most} more key(s)" if len(found) > most else ""
    return "; ".join(found[:most]) + more


def cmd_run(args):
    from sphcore.runner import load_checkpoint, run  # (numba: only where a run starts)
    from sphcore import parallel

    if parallel.launched_ranks() > 1 and args.profile:
        raise SceneError("--profile runs on one rank: leave out mpiexec")
    scene = Scene.load(args.scene) if args.scene else None
    checkpoint = None
    if args.resume:
        out = Path(args.resume)
        stored, checkpoint = load_checkpoint(out)
        if scene is not None and scene.config != stored.config:
            raise CheckpointError(f"{args.scene} is not the scene of the run in {out} (its scene.json): "
                                  f"{differences(scene.config, stored.config, args.scene)}; "
                                  f"leave SCENE out to continue that run")
        scene = stored
    else:
        out = Path(args.out or Path("runs") / scene["name"])
    backend = args.backend or (str(checkpoint["backend"]) if checkpoint is not None else "numba")
    resumed = f" (resumed at step {int(checkpoint['step'])})" if checkpoint is not None else ""
    if parallel.launched_ranks() > 1:  # under mpiexec -n N: one run decomposed over the ranks (sphcore.parallel)
        arrays = parallel.main(dict(scene=scene, steps=args.steps, out_dir=out, overwrite=args.overwrite,
                                    local_size=args.local_size, backend=backend, device=args.device,
                                    checkpoint=checkpoint))
        if arrays is not None:
            print(f"{len(arrays['position'])} particles, {int(arrays['step'])} steps{resumed} on "
                  f"{parallel.launched_ranks()} ranks, t = {float(arrays['time']):.4g} s -> {out}/final.npz")
        return
    options = {"local_size": args.local_size}
    if args.profile:  # a profile.json of someone else's stops the run before it starts, not after
        if (out / "profile.json").exists() and "profile.json" not in (folder.listed(out) or ()):
            raise folder.FolderError(f"{out / 'profile.json'}: a file no sphcore run wrote (no {folder.MANIFEST} "
                                     "lists it); --profile never replaces it: move it away, or give another --out")
        from sphcore.profile import Profile
        options["profile"] = Profile()
    if backend == "vulkan":
        options.update(device=args.device, validation=args.validation or None)
    arrays = run(scene, backend, steps=args.steps, out_dir=out, checkpoint=checkpoint, overwrite=args.overwrite,
                 **options)
    if args.profile:
        from sphcore.profile import work
        per_stage, pairs = work(scene, arrays["position"])
        with folder.RunFolder(out) as run_folder:  # profile.json is the run's: listed in its manifest
            run_folder.write_bytes("profile.json", options["profile"].to_json(per_stage, pairs).encode())
        print(options["profile"].table(per_stage, pairs))
    builds = f", neighbour lists built {int(arrays['list_builds'])} times" if "list_builds" in arrays else ""
    print(f"{len(arrays['position'])} particles, {int(arrays['step'])} steps{resumed}{builds}, "
          f"t = {float(arrays['time']):.4g} s -> {out}/final.npz, {out}/{scene['name']}.pvd")


def cmd_keys(args):
    schema, prefix = SCHEMA, ""
    if args.section:
        tables = sorted(name for name, key in SCHEMA.items() if isinstance(key, dict))
        if args.section not in tables:
            raise SceneError(f"keys: no section {args.section!r} (sections: {', '.join(tables)})")
        schema, prefix = SCHEMA[args.section], f"{args.section}."
    print(f"{'key':24} {'default':>12}  {'unit':8} {'range':18} meaning")
    print("\n".join(describe_schema(schema, prefix)))


def cmd_plot(args):
    from sphcore.plot import check_target, plot_gauges, plot_state  # (matplotlib: only where a plot is drawn)

    final = Path(args.run_dir) / "final.npz"
    if args.out:  # the picture's path first: a missing folder is its fault, not final.npz's
        check_target(args.out)
    if not final.is_file():
        raise SceneError(f"{final}: no such file; `sphcore run` writes it when a run completes "
                         "(a run that stopped early keeps its snapshots, *.vtp)")
    out = plot_state(final, args.out)  # a damaged final.npz or a path it must not write: SceneError
    print(f"wrote {out}")
    gauges = plot_gauges(args.run_dir)  # (one panel a gauge of RUN_DIR/gauges/*.csv, where the scene has gauges)
    if gauges is not None:
        print(f"wrote {gauges}")


def cmd_render(args):
    try:
        import pyvista  # noqa: F401
    except ImportError:
        sys.exit("sphcore: error: `sphcore render` needs pyvista: pip install -e '.[render]'")
    from sphcore.render import render_run

    out = Path(args.out or Path(args.run_dir) / "render")
    if out.is_dir() and (out.resolve() == Path(args.run_dir).resolve() or (out / folder.MANIFEST).is_file()):
        raise SceneError(f"--out {out}: a run's folder; `sphcore render` writes its meshes and pictures into a "
                         f"folder of their own, apart from the run's files: give another --out "
                         f"(default {Path(args.run_dir) / 'render'})")
    try:
        written = render_run(args.run_dir, out, backend=args.backend, spacing=args.spacing, level=args.level,
                             particles=args.particles, every=args.every, mesh_format=args.format)
    except SceneError:  # render's own one-line errors name their file already
        raise
    except ValueError as e:  # e.g. a --spacing so fine that the sample grid is too large
        raise SceneError(f"{args.run_dir}: {e}") from None
    print(f"wrote {len(written) // 2} frames ({args.format} meshes and PNGs) to {out}")


def main(argv=None):
    parser = argparse.ArgumentParser(prog="sphcore", description=__doc__)
    parser.add_argument("--version", action="version", version=f"sphcore {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("run", help="run a scene (a .toml file or the name of a shipped one), or --resume a run")
    p.add_argument("scene", nargs="?")
    p.add_argument("--resume", metavar="RUN_DIR",
                   help="continue the run in RUN_DIR from its checkpoint (its scene, backend and folder)")
    p.add_argument("--backend", choices=["numba", "vulkan"],
                   help="numba (default) or vulkan; with --resume: the checkpoint's")
    p.add_argument("--steps", type=int, help="total steps, counted from the run's start (default: the scene's time.end, or its time.steps)")
    p.add_argument("--out", help="output folder (default: runs/<scene name>)")
    p.add_argument("--local-size", type=int, default=128, help="work-group size (specialization constant)")
    p.add_argument("--device", help="Vulkan device: index or part of its name (default: a discrete GPU, else any)")
    p.add_argument("--validation", action="store_true", help="enable the Vulkan validation layers")
    p.add_argument("--profile", action="store_true",
                   help="time every stage of the step (Vulkan: GPU timestamps) and write RUN_DIR/profile.json")
    p.add_argument("--overwrite", action="store_true",
                   help=f"replace the run already in --out: the files its manifest ({folder.MANIFEST}) lists are deleted, "
                        f"only under a run's names ({folder.PATTERNS}); files it did not write are kept, and a file of "
                        "those names that no manifest lists stops the run"),
    p.set_defaults(func=cmd_run)
    p = sub.add_parser("keys", help="list every scene key with its default, unit and range")
    p.add_argument("section", nargs="?", help="only this table's keys (physics, domain, fluid, forces, walls, time)")
    p.set_defaults(func=cmd_keys)
    p = sub.add_parser("plot", help="draw RUN_DIR/final.npz as a PNG, and the gauges (RUN_DIR/gauges/*.csv) to RUN_DIR/gauges.png")
    p.add_argument("run_dir")
    p.add_argument("--out", help="PNG path (default: RUN_DIR/final.png)")
    p.set_defaults(func=cmd_plot)
    p = sub.add_parser("render", help="surface meshes and pictures of every snapshot of a 3D run (offscreen)")
    p.add_argument("run_dir")
    p.add_argument("--out", help="output folder (default: RUN_DIR/render)")
    p.add_argument("--backend", choices=["numba", "vulkan"], default="numba", help="where the surface is extracted")
    p.add_argument("--spacing", type=float, help="sample spacing in metres (default: h / 2)")
    p.add_argument("--level", type=float, default=0.5, help="isolevel of the colour field (default 0.5)")
    p.add_argument("--particles", action="store_true", help="also draw the particles as points")
    p.add_argument("--every", type=int, default=1, help="render every K-th snapshot (default 1: all)")
    p.add_argument("--format", choices=["vtp", "ply"], default="vtp", help="mesh file format (default vtp)")
    p.set_defaults(func=cmd_render)
    from sphcore.validate.cli import add_commands
    add_commands(sub)  # validate, sweep, report
    args = parser.parse_args(argv)
    if args.command == "run" and not args.scene and not args.resume:
        parser.error("run: give a SCENE, or --resume RUN_DIR")
    if getattr(args, "resume", None) and args.out:
        parser.error("--out cannot be combined with --resume: the run continues in RUN_DIR")
    if getattr(args, "steps", None) is not None and args.steps < 0:
        parser.error(f"--steps must be >= 0, got {args.steps}")
    if not 1 <= getattr(args, "local_size", 1) <= 1024:
        parser.error(f"--local-size must be within [1, 1024] (a work group), got {args.local_size}")
    if getattr(args, "every", 1) < 1:
        parser.error(f"--every must be >= 1, got {args.every}")
    if getattr(args, "spacing", None) is not None and not args.spacing > 0:
        parser.error(f"--spacing must be > 0, got {args.spacing}")
    if getattr(args, "level", None) is not None and not math.isfinite(args.level):
        parser.error(f"--level must be a finite number, got {args.level}")
    if getattr(args, "resume", None) and getattr(args, "overwrite", False):
        parser.error("--overwrite cannot be combined with --resume: a resume continues the run in RUN_DIR")

    try:
        args.func(args)
    except (SceneError, SimulationError, VulkanError, ShaderCompileError) as e:
        print(f"sphcore: error: {printable(e)}", file=sys.stderr)
        return 1
    except BrokenPipeError:  # output piped into a reader that stopped early (`sphcore keys | head`)
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except OSError as e:  # a folder that is a file, a full disk, no permission: files already written are kept
        print(f"sphcore: error: {printable(str(e.filename) + ': ' if e.filename else '')}{e.strerror or e}",
              file=sys.stderr)
        return 1
    except MemoryError as e:  # past the estimate of sphcore.memory: files already written are kept
        print(f"sphcore: error: out of memory ({str(e) or 'MemoryError'}); files written so far are complete",
              file=sys.stderr)
        return 1
    except KeyboardInterrupt as e:  # Ctrl-C, or SIGTERM during a run (sphcore.simulation.Interrupted)
        print(f"sphcore: {str(e) or 'interrupted; files written so far are complete'}", file=sys.stderr)
        return 128 + getattr(e, "signum", signal.SIGINT)
    return 0


if __name__ == "__main__":
    sys.exit(main())
