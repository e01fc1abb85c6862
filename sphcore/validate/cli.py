"""Subcommands `sphcore validate ...`, `sphcore sweep` and `sphcore report` (added to sphcore.cli)."""
from pathlib import Path

from sphcore.scene import SceneError


def cmd_dam_break(args):
    from sphcore.validate import dam_break

    settings = {k: v for k, v in vars(args).items() if k in dam_break.SETTINGS and v is not None}
    out = Path(args.out)
    rows, summary = dam_break.run_dam_break(settings, out)
    try:
        png = dam_break.plot(rows, summary, out / f"dam_break_{summary['settings']['dimension']}d.png")
    except ImportError:
        png = "no PNG: matplotlib is not installed (pip install matplotlib)"
    print(f"{summary['particles']} particles, {summary['steps']} steps of {summary['dt']:.3g} s in {summary['wall_s']:.1f} s; "
          f"RMS of Z against Martin & Moyce Table 2: {summary['rms_Z_table2']:.3f} ({summary['points_table2']} points, "
          f"simulated T + {summary['gate_shift_T']:g}; unshifted {summary['rms_Z_table2_unshifted']:.3f}) -> {png}")


def physics_settings(args, keys):
    """The settings of `keys` given on the command line, with the configuration and its switches."""
    from sphcore.validate import configs

    names = set(keys) | {"config", *configs.OPTIONS}
    return {k: v for k, v in vars(args).items() if k in names and v is not None and v is not False}


def plotted(plot, rows, summary, path):
    """plot(rows, summary, path), or why there is no PNG (no matplotlib: the GPU machine)."""
    try:
        return plot(rows, summary, path)
    except ImportError:
        return "no PNG: matplotlib is not installed (pip install matplotlib)"


def cmd_dam_break_pressure(args):
    from sphcore.validate import buchner

    out = Path(args.out)
    rows, summary = buchner.run_buchner(physics_settings(args, buchner.SETTINGS), out)
    png = plotted(buchner.plot, rows, summary, out / "dam_break_pressure.png")
    met = ", ".join(f"{k} {'met' if v else 'not met'}" for k, v in summary["meets"].items())
    print(f"{summary['particles']} particles, {summary['steps']} steps in {summary['wall_s']:.1f} s; P1 against Buchner "
          f"2002: impact peak t* {summary['peak_t_star']:.3f} ({100 * summary['peak_time_error']:+.1f} %), p* "
          f"{summary['peak_p_star']:.3f} ({100 * summary['peak_height_error']:+.0f} %), RMS {summary['rms_p_star']:.3f} "
          f"({summary['rms_points']} points); targets: {met}; against De Courcy et al. 2024's simulation, RMS "
          + ", ".join(f"{1000 * r['y']:g} mm {r['rms_p_star']:.3f} ({r['rms_p_star_calm']:.3f} to t* "
                      f"{buchner.CALM_UNTIL:g})" for r in summary["reference"].values()) + f" -> {png}")


def cmd_tank(args):
    from sphcore.validate import tank

    out = Path(args.out)
    rows, summary = tank.run_tank(physics_settings(args, tank.SETTINGS), out)
    png = plotted(tank.plot, rows, summary, out / "tank.png")
    met = ", ".join(f"{k} {'met' if v else 'not met'}" for k, v in summary["meets"].items())
    print(f"{summary['particles']} particles, {summary['steps']} steps in {summary['wall_s']:.1f} s; at t = "
          f"{rows[-1]['t']:.3g} s: slope {100 * summary['slope_error']:+.2f} % of rho g, largest deviation "
          f"{100 * summary['deviation_max']:.2f} % of rho g D, wall sensors within "
          f"{100 * summary['sensor_error_max']:.2f} %; targets: {met} -> {png}")


def cmd_bodies(args):
    from sphcore.validate import bodies

    out = Path(args.out)
    unknown = sorted(set(args.case or ()) - set(bodies.CASES))
    if unknown:
        raise SceneError(f"--case {unknown[0]}: no such case (known: {', '.join(bodies.CASES)})")
    common = {k: v for k, v in (("backend", args.backend), ("device", args.device)) if v is not None}
    for case in args.case or bodies.CASES:
        settings = {**common, **({"spacing": args.spacing} if args.spacing and "spacing" in bodies.SETTINGS[case]
                                 else {}), **({"t_end": args.t_end} if args.t_end else {}),
                    **({"resolution": args.resolution} if args.resolution and case == "inclined_dam_break" else {})}
        rows, summary = bodies.CASES[case](settings, out)
        png = plotted(bodies.plot, rows, summary, out / f"{case}.png")
        print(f"{case}: {bodies.describe(summary)} -> {png}")


def cmd_spheric(args):
    from sphcore.validate import spheric

    settings = physics_settings(args, ("backend", "device", "spacing", "t_end", "dt_fraction", "obstacle"))
    rows, summary = spheric.run_spheric(settings, args.out)
    png = plotted(spheric.plot, rows, summary, Path(args.out) / "spheric_test2.png")
    rms = ", ".join(f"{g} {summary[f'rms_{g}']:.3f}" for g in spheric.GAUGES)
    print(f"{summary['particles']} particles, {summary['steps']} steps of {summary['dt']:.3g} s in {summary['wall_s']:.1f} s "
          f"on {summary['device']}; RMS of the heights against Kleefsman et al. 2005 (m): {rms} -> {png}")


def cmd_sweep(args):
    from sphcore.validate import sweep

    rows = sweep.run_sweep(args.out, scheduler=args.scheduler, workers=args.workers, quick=args.quick,
                           backends=args.backends)
    ok = sum(r["status"] == "ok" for r in rows)
    print("\n".join(sweep.recommendations(rows)["text"][1:3]))
    print(f"{ok} of {len(rows)} points ok -> {args.out}/sweep.csv, sweep.json, pareto.png, recommendations.json")


def cmd_report(args):
    from sphcore.validate import report

    path = report.build_report(args.out, results=args.results)
    print(f"wrote {path}")


def backend_list(text):
    names = [n.strip() for n in text.split(",") if n.strip()]
    unknown = [n for n in names if n not in ("numba", "vulkan")]
    if unknown or not names:
        raise ValueError
    return names


backend_list.__name__ = "list of backends (numba, vulkan)"


def cmd_stability(args):
    from sphcore.validate import stability

    options = {"device": args.device} if args.backend == "vulkan" else {}
    unknown = sorted(set(args.case or ()) - set(stability.cases()))
    if unknown:
        raise SceneError(f"--case {unknown[0]}: no such case (known: {', '.join(stability.cases())})")
    rows = stability.run_matrix(args.out, args.backend, only=args.case, largest=args.largest, **options)
    for r in rows:
        where = f" at step {r['step']}, particle {r['particle']}: {r['cause']}" if r["status"] == "detected" else ""
        print(f"{r['case']:18} {r['status']:8}{where}")
    print(f"-> {args.out}/stability.json, stability.csv")


def positive(kind):
    def parse(text):
        value = kind(text)
        if not 0 < value < float("inf"):  # inf, nan: no run ends
            raise ValueError
        return value
    parse.__name__ = f"positive {kind.__name__}"
    return parse


def add_model_options(d):
    """The options the pressure cases share beside their own: precision, equation of state, alpha,
    dt fraction and the physics switches."""
    d.add_argument("--precision", choices=["float32", "float64"])
    d.add_argument("--equation-of-state", choices=["linear", "tait"])
    d.add_argument("--alpha", type=positive(float), help="viscosity alpha (default 0.02)")
    d.add_argument("--dt-fraction", type=positive(float), help="fraction of the stability bound (default 1)")
    add_physics_options(d)


def add_physics_options(p):
    """--config and the physics switches of issue 12 (sphcore.validate.configs)."""
    from sphcore.validate import configs

    p.add_argument("--config", choices=list(configs.CONFIGS), help="named model configuration (default "
                   f"{configs.DEFAULT_CONFIG}: the scenes' defaults; {configs.RECOMMENDED_CONFIG}: the recommended "
                   "model); the options below override it")
    p.add_argument("--kernel", choices=configs.choices("kernel"), help="physics.kernel")
    p.add_argument("--density", choices=configs.choices("density"), help="physics.density")
    p.add_argument("--density-diffusion", choices=configs.choices("density_diffusion"), help="physics.density_diffusion")
    p.add_argument("--delta", type=positive(float), help="fluid.density_diffusion: the diffusion coefficient delta")
    p.add_argument("--viscosity-model", choices=configs.choices("viscosity_model"), help="physics.viscosity_model")
    p.add_argument("--wall-model", choices=configs.choices("wall_model"), help="domain.wall_model")
    p.add_argument("--integrator", choices=configs.choices("integrator"), help="time.integrator")
    p.add_argument("--adaptive-dt", action="store_true", help='time.dt = "adaptive": the step chosen on the device')
    p.add_argument("--pressure-solver", choices=configs.choices("pressure_solver"), help="physics.pressure_solver "
                   "(dfsph: incompressible, dt from time.cfl_number on the particle speed)")
    p.add_argument("--relaxation", type=positive(float), help="fluid.relaxation: DFSPH's share omega of each Jacobi "
                   "update (0 < omega <= 1)")
    p.add_argument("--cfl-number", type=positive(float), help="time.cfl_number: DFSPH's step, dt = cfl_number dx / "
                   "the fastest particle's speed (default 0.4, at most 1)")
    p.add_argument("--shifting", choices=configs.choices("shifting"), help="physics.shifting (lind: Lind et al. "
                   "2012's particle shifting, coefficient fluid.shifting)")


def add_commands(sub):
    """Add `validate` (with its cases), `sweep` and `report` to the subparsers `sub` of `sphcore`."""
    from sphcore.validate.dam_break import SETTINGS

    p = sub.add_parser("validate", help="run a validation case against published experiments")
    cases = p.add_subparsers(dest="case", required=True)
    d = cases.add_parser("dam-break", help="Martin & Moyce (1952) column collapse: front and column height")
    d.add_argument("--out", required=True, help="output folder (CSV, JSON, PNG)")
    d.add_argument("--backend", choices=["numba", "vulkan"], help=f"(default {SETTINGS['backend']})")
    d.add_argument("--device", help="Vulkan device: index or part of its name")
    d.add_argument("--dimension", type=int, choices=[2, 3], help="(default 2; 3: a channel a few particles deep)")
    d.add_argument("--resolution", type=positive(int), help=f"particles across the column width a (default {SETTINGS['resolution']})")
    d.add_argument("--precision", choices=["float32", "float64"])
    d.add_argument("--equation-of-state", choices=["linear", "tait"])
    d.add_argument("--stiffness", type=positive(float), help=f"k = c^2 in m^2/s^2 (default {SETTINGS['stiffness']:g})")
    d.add_argument("--alpha", type=float, help=f"viscosity as alpha of mu = alpha rho_0 c h / (2 dim + 4) (default {SETTINGS['alpha']:g})")
    d.add_argument("--viscosity", type=float, help="Pa s (replaces --alpha)")
    d.add_argument("--dt-fraction", type=positive(float), help="fraction of the stability bound (default 1)")
    d.add_argument("--neighbour-search", choices=["grid", "all_pairs"])
    d.add_argument("--t-end", type=positive(float), help=f"simulated seconds (default {SETTINGS['t_end']:g})")
    d.add_argument("--depth", type=positive(int), help=f"3D: particles across the channel (default {SETTINGS['depth']})")
    d.add_argument("--smoothing-ratio", type=positive(float), help="h / dx (default 2; seed 2: 2.857)")
    add_physics_options(d)
    d.set_defaults(func=cmd_dam_break)
    d = cases.add_parser("dam-break-pressure", help="Zhou et al. 1999 / Buchner 2002: the impact pressure at P1 on the "
                         "downstream wall against the measured series")
    d.add_argument("--out", required=True, help="output folder (dam_break_pressure.csv, .json, .png)")
    d.add_argument("--backend", choices=["numba", "vulkan"], help="(default numba)")
    d.add_argument("--device", help="Vulkan device: index or part of its name")
    d.add_argument("--resolution", type=positive(int), help="particles per column height H = 0.6 m (default 40)")
    d.add_argument("--t-end-star", type=positive(float), help="simulated t sqrt(g/H) (default 7.3, the data's end)")
    add_model_options(d)
    d.set_defaults(func=cmd_dam_break_pressure)
    d = cases.add_parser("tank", help="water at rest: the settled pressure against rho g depth")
    d.add_argument("--out", required=True, help="output folder (tank.csv, .json, .png)")
    d.add_argument("--backend", choices=["numba", "vulkan"], help="(default numba)")
    d.add_argument("--device", help="Vulkan device: index or part of its name")
    d.add_argument("--resolution", type=positive(int), help="particles per depth (0.6 m; default 30)")
    d.add_argument("--t-end", type=positive(float), help="simulated seconds of settling (default 2)")
    add_model_options(d)
    d.set_defaults(func=cmd_tank)
    d = cases.add_parser("bodies", help="bodies, wall particles and gauges: water at rest in a rotated and a "
                         "cylindrical tank, the forces on a tank's walls, Martin & Moyce in an inclined tank")
    d.add_argument("--out", required=True, help="output folder (CASE.csv, .json, .png for each case)")
    d.add_argument("--case", action="append", help="run only this case (repeatable): rotated_tank, cylindrical_tank, "
                   "forces_at_rest, inclined_dam_break (default: all)")
    d.add_argument("--backend", choices=["numba", "vulkan"], help="(default numba)")
    d.add_argument("--device", help="Vulkan device: index or part of its name")
    d.add_argument("--spacing", type=positive(float), help="dx in m of the tanks at rest (defaults: 0.01 in 2D, "
                   "0.035 in 3D)")
    d.add_argument("--resolution", type=positive(int), help="inclined dam break: particles across a (default 40)")
    d.add_argument("--t-end", type=positive(float), help="simulated seconds (defaults: 1 at rest, 0.5 dam break)")
    d.set_defaults(func=cmd_bodies)
    d = cases.add_parser("stability", help="the stability matrix: every parameter at its extremes")
    d.add_argument("--out", required=True, help="output folder (a folder of snapshots per case, stability.json/.csv)")
    d.add_argument("--backend", choices=["numba", "vulkan"], default="numba")
    d.add_argument("--device", help="Vulkan device: index or part of its name")
    d.add_argument("--case", action="append", help="run only this case (repeatable)")
    d.add_argument("--largest", action="store_true", help="also the largest particle count the memory allows (GPU)")
    d.set_defaults(func=cmd_stability)
    s = cases.add_parser("spheric", help="SPHERIC test 2 (Kleefsman et al. 2005): 3D dam break hitting a box, "
                         "water heights H1-H4 and pressures P1-P8")
    s.add_argument("--out", required=True, help="output folder (spheric_test2.csv, .json, .png)")
    s.add_argument("--backend", choices=["numba", "vulkan"], help="(default numba)")
    s.add_argument("--device", help="Vulkan device: index or part of its name")
    s.add_argument("--spacing", type=positive(float), help="particle spacing dx in m (default 0.02: 85,400 particles)")
    s.add_argument("--t-end", type=positive(float), help="simulated seconds (default 6)")
    s.add_argument("--dt-fraction", type=positive(float), help="fraction of the stability bound (default 0.5)")
    s.add_argument("--obstacle", choices=["box", "mesh"], help="the box as domain.obstacles (mirror images; the "
                   "default) or as a body from scenes/meshes/spheric_box.stl (wall particles; its force recorded)")
    add_physics_options(s)
    s.set_defaults(func=cmd_spheric)

    p = sub.add_parser("sweep", help="speed/accuracy sweep of the 2D dam break through Dask: table, Pareto front, "
                       "recommendations")
    p.add_argument("--out", required=True, help="output folder (sweep.csv/json, pareto.png, recommendations.json/txt); "
                   "points already there with status ok are not run again")
    p.add_argument("--scheduler", metavar="ADDRESS", help="a Dask scheduler (tcp://host:8786) whose workers run "
                   "the points (default: a local cluster)")
    p.add_argument("--workers", type=positive(int), help="local cluster: worker processes, the cores shared "
                   "among them as numba threads (default 1)")
    p.add_argument("--backends", type=backend_list, default=["numba"], help="comma-separated: numba,vulkan "
                   "(default numba; Vulkan on a CPU device gets a few small points)")
    p.add_argument("--quick", action="store_true", help="a small design (resolution 8-10, 0.1 s) for tests and CI")
    p.set_defaults(func=cmd_sweep)
    p = sub.add_parser("report", help="an HTML page of the validation results: plots, tables, settings, versions, "
                       "hardware")
    p.add_argument("--out", required=True, help="output folder: index.html and its images")
    p.add_argument("--results", action="append", help="a folder the results are read from, before --out "
                   "(repeatable: the first that has a file is used); the 2D dam break is run into --out where none has it")
    p.set_defaults(func=cmd_report)
