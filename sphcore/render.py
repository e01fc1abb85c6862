"""Pictures and meshes of the fluid surface, offscreen, with pyvista.

`render_run(run_dir, out_dir)` takes every snapshot of a 3D run, extracts the surface
(`particle_surface`: the isosurface of the colour field), and writes next to each other
<name>_surface_<step>.png and <name>_surface_<step>.vtp (or .ply), the camera fixed for the whole
run, and <name>_surface.pvd, which gives ParaView each mesh's time. These names never are a run's
(its snapshots are <name>_<step>.vtp, or <name>_<step>.pvtp of the MPI driver, whose pieces
<name>_<step>_p<rank>.vtp are joined): an out_dir where one would be is refused. A run with bodies
has their wall particles in walls.vtp: each picture draws them in grey, about a spacing wide.

Offscreen: with no X display, VTK is pointed at its EGL render window (Mesa's llvmpipe through
EGL's surfaceless platform: apt packages libegl1, libegl-mesa0, libgl1-mesa-dri; no GPU and no
X server needed), unless VTK_DEFAULT_OPENGL_WINDOW is already set.
"""
import json
import os
import re
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
from tqdm import tqdm

from sphcore import output
from sphcore.errors import SceneError
from sphcore.folder import listed, names_of_run
from sphcore.output import entry_step
from sphcore.plot import read_final
from sphcore.scene import Scene
from sphcore.surface import particle_surface

if not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
    os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")

BACKGROUND = "white"
WATER = (0.16, 0.47, 0.80)
WALL = (0.62, 0.62, 0.62)  # the bodies' wall particles: a neutral grey
VIEW_ANGLE = 30.0  # degrees, vertical (VTK's default)


def replace_into(path, write):
    """Call write(tmp) with a temporary name in path's folder (same suffix, so writers that go by
    the suffix pick the right format), then rename it over `path`: readers see all or nothing."""
    path = Path(path)
    tmp = path.with_name(f".{path.stem}.tmp-{os.getpid()}{path.suffix}")
    try:
        write(tmp)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def surface_mesh(verts, faces, normals):
    """pyvista PolyData of a marching-cubes surface, with its outward normals as the active point
    normals. The faces are flipped (scikit-image's winding has the right-hand normal pointing into
    the fluid), so that in the mesh the winding and the normals both point outwards."""
    import pyvista as pv

    faces = np.asarray(faces, np.int64).reshape(-1, 3)[:, ::-1]
    cells = np.hstack([np.full((len(faces), 1), 3, np.int64), faces]).ravel()
    mesh = pv.PolyData(np.asarray(verts, np.float32).reshape(-1, 3), cells)
    if len(verts):
        mesh.point_data["Normals"] = np.asarray(normals, np.float32).reshape(-1, 3)
        mesh.point_data.active_normals_name = "Normals"
    return mesh


def box_camera(box_min, box_max, up=(0.0, 1.0, 0.0), aspect=4 / 3, direction=(0.45, 0.7, 1.0)):
    """pyvista camera position (position, focal point, view up) looking at the box's centre from
    `direction` (in the frame: x, `up`, their cross product; default from the front, above and to
    the right), just far enough that all 8 corners fit in the view (VIEW_ANGLE, `aspect`)."""
    lo, hi = np.asarray(box_min, float), np.asarray(box_max, float)
    centre = (lo + hi) / 2
    u = np.asarray(up, float) / np.linalg.norm(up)
    a = np.eye(3)[int(np.argmin(np.abs(u)))]  # the axis least aligned with up: x for up = y
    a = a - (a @ u) * u
    a /= np.linalg.norm(a)
    d = direction[0] * a + direction[1] * u + direction[2] * np.cross(a, u)
    d /= np.linalg.norm(d)  # from the focal point towards the camera
    right = np.cross(-d, u)
    right /= np.linalg.norm(right)
    true_up = np.cross(right, -d)
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]) - centre
    ty = np.tan(np.radians(VIEW_ANGLE / 2))
    tx = ty * aspect
    dist = max(np.max(corners @ d + np.abs(corners @ right) / tx), np.max(corners @ d + np.abs(corners @ true_up) / ty))
    dist *= 1.08  # a margin
    return (tuple(centre + dist * d), tuple(centre), tuple(true_up))


def render_mesh(verts, faces, normals, png_path, particles=None, box=None, camera=None, window_size=(1024, 768),
                text=None, walls=None, wall_size=4.0):
    """Draw the surface (verts, faces, normals as from particle_surface / marching_cubes) shaded
    and lit with its own vertex normals, optionally `particles` (N, 3) as small points, `walls` (N, 3)
    as grey spheres `wall_size` pixels wide, the outline of `box` = (box_min, box_max), and `text`
    at the top left, from `camera` (pyvista's (position, focal point, view up); None: box_camera
    of `box`, else fitted to the mesh), and write the screenshot to `png_path` atomically. An
    empty surface draws the rest.

    >>> import os, tempfile, numpy as np, sphcore
    >>> z, y, x = np.mgrid[-1:1:16j, -1:1:16j, -1:1:16j]
    >>> verts, faces, normals = sphcore.marching_cubes(x**2 + y**2 + z**2, level=0.5)
    >>> png = os.path.join(tempfile.mkdtemp(), "sphere.png")
    >>> sphcore.render_mesh(verts, faces, normals, png, box=((0, 0, 0), (15, 15, 15)), window_size=(320, 240)).name
    'sphere.png'
    >>> open(png, "rb").read(4)[1:]  # a PNG file's signature
    b'PNG'
    """
    import pyvista as pv

    mesh = surface_mesh(verts, faces, normals)
    pl = pv.Plotter(off_screen=True, window_size=list(window_size), lighting="none")
    try:
        # a key light above left of the camera, a weaker one from the camera (fills the shadows)
        pl.add_light(pv.Light(position=(-1.0, 1.5, 1.0), light_type="camera light", intensity=0.85))
        pl.add_light(pv.Light(light_type="headlight", intensity=0.35))
        pl.set_background(BACKGROUND)
        if mesh.n_cells:
            pl.add_mesh(mesh, color=WATER, smooth_shading=False, interpolation="phong", ambient=0.15, diffuse=0.8,
                        specular=0.6, specular_power=40.0, show_scalar_bar=False)
        if particles is not None and len(particles):
            pl.add_mesh(pv.PolyData(np.asarray(particles, np.float32)[:, :3]), color=(0.05, 0.15, 0.35),
                        point_size=2.0, render_points_as_spheres=False)
        if walls is not None and len(walls):
            pl.add_mesh(pv.PolyData(np.asarray(walls, np.float32)[:, :3]), color=WALL, point_size=float(wall_size),
                        render_points_as_spheres=True, ambient=0.3, diffuse=0.7)
        if box is not None:
            lo, hi = np.asarray(box[0], float), np.asarray(box[1], float)
            pl.add_mesh(pv.Box(bounds=(lo[0], hi[0], lo[1], hi[1], lo[2], hi[2])).outline(),
                        color=(0.35, 0.35, 0.35), line_width=2.0)
        if text:
            pl.add_text(text, position=(12, window_size[1] - 32), font_size=12, color="black")
        if camera is None and box is not None:
            camera = box_camera(box[0], box[1], aspect=window_size[0] / window_size[1])
        if camera is not None:
            pl.camera_position = [tuple(map(float, v)) for v in camera]
            pl.camera.view_angle = VIEW_ANGLE
            pl.reset_camera_clipping_range()
        elif mesh.n_points:
            pl.reset_camera(bounds=mesh.bounds)
        return replace_into(png_path, lambda tmp: pl.screenshot(str(tmp)))
    finally:
        pl.close()


def read_scene(run_dir):
    """The scene of a run folder, from its scene.json or else its final.npz, or SceneError naming
    the file and what is wrong with it (missing, truncated, not sphcore's)."""
    run_dir = Path(run_dir)
    if (run_dir / "scene.json").is_file():
        source = run_dir / "scene.json"
        try:
            text = source.read_text(encoding="utf-8")
            data = json.loads(text)
        except (OSError, ValueError) as e:  # unreadable, not UTF-8, not JSON
            raise SceneError(f"{source}: not a readable scene ({str(e)[:200]})") from None
    elif (run_dir / "final.npz").is_file():
        source = run_dir / "final.npz"
        data = read_final(source)["config"]  # (checked member by member, never unpickled)
    else:
        raise SceneError(f"{run_dir}: no scene.json or final.npz, so no scene to render; is it a `sphcore run` folder?")
    if not isinstance(data, dict):
        raise SceneError(f"{source}: not a scene (a JSON {type(data).__name__}, not a table)")
    return Scene.from_dict(data, str(source))


def read_pvd(pvd):
    """[(file name, time)] of a .pvd's data sets, or SceneError naming the file (truncated, not XML,
    a time that is no number)."""
    try:
        return output.read_pvd(pvd)
    except (OSError, ET.ParseError, ValueError) as e:
        raise SceneError(f"{pvd}: not a readable .pvd series ({str(e)[:200]})") from None


def load_run(run_dir):
    """(scene, snapshot paths in step order, file name -> time) of a run folder, or SceneError saying
    what is missing or unreadable. Snapshots its .pvd lists that are gone are left out, with a note."""
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise SceneError(f"{run_dir}: no such run folder (`sphcore run SCENE --out {run_dir}` writes one)")
    scene = read_scene(run_dir)
    if scene.dim != 3:
        raise SceneError(f"{run_dir}: {scene['name']} is a 2D run; `sphcore render` draws 3D surfaces, "
                         f"use `sphcore plot {run_dir}` for 2D")
    pvd = run_dir / f"{scene['name']}.pvd"
    times = dict(read_pvd(pvd)) if pvd.is_file() else {}
    if pvd.is_file():
        files = [run_dir / name for name in times]
    else:  # NAME_NNNNNNN.vtp or .pvtp, not NAME_surface_NNNNNNN.vtp nor a piece NAME_NNNNNNN_pR.vtp
        snapshot = re.compile(re.escape(scene["name"]) + r"_\d+\.p?vtp")
        files = [f for f in run_dir.glob(f"{scene['name']}_*vtp") if snapshot.fullmatch(f.name)]
    gone = [f.name for f in files if not f.is_file()]
    if gone:
        print(f"sphcore render: note: {pvd} lists {len(gone)} snapshot(s) that are gone ({gone[0]}"
              f"{', ...' if len(gone) > 1 else ''}); rendering the others", file=sys.stderr)
    files = sorted({f for f in files if f.is_file() and entry_step(f) >= 0}, key=entry_step)
    if not files:
        raise SceneError(f"{run_dir}: no snapshots ({scene['name']}_<step>.vtp or .pvtp) to render")
    return scene, files, times


def pieces(path):
    """The pieces of parallel snapshot `path` (a .pvtp): the .vtp files its <Piece Source=...> name, beside
    it, or SceneError naming it (and the piece that is missing)."""
    path = Path(path)
    try:
        sources = [p.get("Source") for p in ET.parse(path).getroot().findall("PPolyData/Piece")]
    except (OSError, ET.ParseError) as e:
        raise SceneError(f"{path}: not a readable parallel snapshot ({str(e)[:200]})") from None
    if not sources or not all(s and s.endswith(".vtp") for s in sources):
        raise SceneError(f"{path}: not a readable parallel snapshot (no <Piece Source=...> naming a .vtp)")
    for s in sources:
        if not (path.parent / s).is_file():
            raise SceneError(f"{path}: its piece {s} is missing (a .pvtp's pieces lie beside it)")
    return [path.parent / s for s in sources]


def each_piece(path, read):
    """[read(piece)] for each piece of parallel snapshot `path`; a piece's SceneError is named as the .pvtp's."""
    done = []
    for piece in pieces(path):
        try:
            done.append(read(piece))
        except SceneError as e:
            raise SceneError(f"{path}: piece {e}") from None
    return done


def read_positions(path):
    """Particle positions (N, 3) float32 of a .vtp snapshot, or of a .pvtp (its pieces' joined, in the order
    it names them), or SceneError naming the file: a truncated or garbled file, or one with fewer points than
    its header says; for a .pvtp, also a missing piece."""
    if Path(path).suffix == ".pvtp":
        return np.concatenate(each_piece(path, read_positions))
    import pyvista as pv
    from pyvista.core.utilities import VtkErrorCatcher
    from vtkmodules.vtkIOXML import vtkXMLPolyDataReader

    try:  # the whole XML first: VTK reads a truncated file as an empty one with only a log message
        piece = ET.parse(path).getroot().find("PolyData/Piece")
        n = int(piece.get("NumberOfPoints"))
    except (OSError, ET.ParseError, AttributeError, TypeError, ValueError) as e:
        raise SceneError(f"{path}: not a readable snapshot, truncated or not a .vtp ({str(e)[:200]})") from None
    try:
        reader = vtkXMLPolyDataReader()  # not pv.read: its own observer logs VTK's errors and warns
        reader.SetFileName(str(path))
        with pv.vtk_verbosity("off"), VtkErrorCatcher(raise_errors=True, send_to_logging=False):
            reader.Update()
        points = np.asarray(pv.wrap(reader.GetOutput()).points, np.float32).reshape(-1, 3)
    except Exception as e:  # VTK's errors, raised by the catcher: say the first one, less its source line
        lines = [s for s in str(e).splitlines() if s.strip() and not s.startswith("ERROR: In ")] or [type(e).__name__]
        what = re.sub(r"^vtk\w+ \(0x[0-9a-f]+\): ", "", lines[0])[:200]
        raise SceneError(f"{path}: not a readable snapshot ({what})") from None
    if points.shape != (n, 3):
        raise SceneError(f"{path}: not a readable snapshot: {len(points)} points where its header says {n}")
    return points


def check_complete(path):
    """SceneError naming a snapshot that does not end in </VTKFile> (a truncated file), or a .pvtp with
    such a piece or a missing one: checked for every snapshot before the first frame is drawn, the whole
    file only when it is read."""
    if Path(path).suffix == ".pvtp":
        each_piece(path, check_complete)
    try:
        with open(path, "rb") as f:
            f.seek(max(f.seek(0, os.SEEK_END) - 64, 0))
            complete = f.read().rstrip().endswith(b"</VTKFile>")
    except OSError as e:
        raise SceneError(f"{path}: not a readable snapshot ({e.strerror or e})") from None
    if not complete:
        raise SceneError(f"{path}: not a readable snapshot, truncated (it does not end in </VTKFile>)")


def surface_name(scene_name, snapshot):
    """The stem of the surface of snapshot NAME_NNNNNNN.vtp or .pvtp: NAME_surface_NNNNNNN (never a run's name)."""
    return f"{scene_name}_surface_{entry_step(snapshot):07d}"


def refuse_clash(out_dir, names):
    """SceneError (one line) if a file `names` would give in out_dir is, or will be, a run's: one that
    out_dir's run manifest lists, or a name a run of the scene in out_dir/scene.json writes."""
    out_dir = Path(out_dir)
    if not out_dir.is_dir():
        return
    theirs = listed(out_dir) or set()
    try:
        theirs |= set(filter(names_of_run(json.loads((out_dir / "scene.json").read_text(encoding="utf-8"))["name"]),
                             names))
    except (OSError, ValueError, KeyError, TypeError):
        pass  # no run's scene there
    clash = sorted(set(names) & theirs)
    if clash:
        raise SceneError(f"{out_dir}: holds a run whose file names `sphcore render` would write over "
                         f"({clash[0]}{' and more' if len(clash) > 1 else ''}); give another --out")


def write_pvd(path, entries):
    """A .pvd series of [(file name, time)], atomically."""
    data = output.pvd_bytes(entries)
    return replace_into(path, lambda tmp: Path(tmp).write_bytes(data))


def render_run(run_dir, out_dir, backend="numba", spacing=None, level=0.5, particles=False, every=1,
               mesh_format="vtp", progress=True):
    """Surface mesh and picture of every `every`-th snapshot NAME_NNNNNNN.vtp or .pvtp of a 3D run:
    out_dir/NAME_surface_NNNNNNN.png and .vtp or .ply (points, triangles wound outwards, point
    normals "Normals"), from one camera fixed by the scene's box, and (vtp, where the run's .pvd
    gives the snapshots' times) out_dir/NAME_surface.pvd listing each mesh with its time, rewritten
    after each frame; the run's walls.vtp (the bodies' wall particles), where there is one, in grey.
    `spacing` (default h / 2) and `level` go to particle_surface. An out_dir holding a run whose
    files these names would replace is refused before anything is written. Returns the paths
    written, in order."""
    if mesh_format not in ("vtp", "ply"):
        raise ValueError(f"mesh_format must be vtp or ply, got {mesh_format!r}")
    if every < 1:
        raise ValueError(f"every must be >= 1, got {every}")
    scene, snapshots, times = load_run(run_dir)
    snapshots = snapshots[::every]
    for path in snapshots:
        check_complete(path)
    name = scene["name"]
    stems = [surface_name(name, path) for path in snapshots]
    series = f"{name}_surface.pvd"
    out_dir = Path(out_dir)
    refuse_clash(out_dir, [series] + [f"{s}.{ext}" for s in stems for ext in (mesh_format, "png")])
    out_dir.mkdir(parents=True, exist_ok=True)
    box = (np.array(scene["domain.box_min"], float), np.array(scene["domain.box_max"], float))
    gravity = np.array(scene["forces.gravity"], float) if scene["physics.gravity"] else np.zeros(3)
    up = -gravity / np.linalg.norm(gravity) if np.linalg.norm(gravity) > 0 else (0.0, 1.0, 0.0)
    window = (1024, 768)
    camera = box_camera(*box, up=up, aspect=window[0] / window[1])
    walls, wall_size = None, 4.0
    wall_file = Path(run_dir) / "walls.vtp"
    if wall_file.is_file():  # the bodies' wall particles, fixed: a spacing wide at the box's centre
        walls = read_positions(wall_file)
        distance = np.linalg.norm(np.subtract(camera[0], camera[1]))
        wall_size = max(2.0, scene["fluid.spacing"] / (2 * distance * np.tan(np.radians(VIEW_ANGLE / 2))) * window[1])
    written, entries = [], []
    for path, stem in tqdm(list(zip(snapshots, stems)), unit="frame", disable=not progress, desc=f"render {name}"):
        position = read_positions(path)
        if len(position):
            verts, faces, normals = particle_surface(scene, position, spacing=spacing, level=level, backend=backend)
        else:  # no fluid left: an empty mesh and a picture of the box
            verts, faces, normals = np.zeros((0, 3), np.float32), np.zeros((0, 3), np.int32), np.zeros((0, 3), np.float32)
        mesh = surface_mesh(verts, faces, normals)
        written.append(replace_into(out_dir / f"{stem}.{mesh_format}", lambda tmp: mesh.save(str(tmp))))
        t = times.get(path.name)
        text = f"{name}  t = {t:.4g} s" if t is not None else f"{name}  {path.stem}"
        written.append(render_mesh(verts, faces, normals, out_dir / f"{stem}.png",
                                   particles=position if particles else None, box=box, camera=camera,
                                   window_size=window, text=text, walls=walls, wall_size=wall_size))
        if mesh_format == "vtp" and t is not None:
            entries.append((f"{stem}.vtp", t))
            write_pvd(out_dir / series, entries)
    if entries:
        written.append(out_dir / series)
    return written

