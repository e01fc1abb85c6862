"""Pictures and meshes of the fluid surface, offscreen, with pyvista.

`render_run(run_dir, out_dir)` takes every snapshot of a 3D run, extracts the surface
(`particle_surface`: the isosurface of the colour field), and writes next to each other
<name>_<step>.png and <name>_<step>.vtp (or .ply), the camera fixed for the whole run.

Offscreen: with no X display, VTK is pointed at its EGL render window (Mesa's llvmpipe through
EGL's surfaceless platform: apt packages libegl1, libegl-mesa0, libgl1-mesa-dri; no GPU and no
X server needed), unless VTK_DEFAULT_OPENGL_WINDOW is already set.
"""
import json
import os
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

if not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
    os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")

BACKGROUND = "white"
WATER = (0.16, 0.47, 0.80)
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
                text=None):
    """Draw the surface (verts, faces, normals as from particle_surface / marching_cubes) shaded
    and lit with its own vertex normals, optionally `particles` (N, 3) as small points, the
    outline of `box` = (box_min, box_max), and `text` at the top left, from `camera` (pyvista's
    (position, focal point, view up); None: box_camera of `box`, else fitted to the mesh), and
    write the screenshot to `png_path` atomically. An empty surface draws the rest."""
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


def load_run(run_dir):
    """(scene, snapshot paths in step order) of a run folder, or SceneError saying what is missing."""
    from sphcore.scene import Scene, SceneError

    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise SceneError(f"{run_dir}: no such run folder (`sphcore run SCENE --out {run_dir}` writes one)")
    if (run_dir / "scene.json").is_file():
        source = run_dir / "scene.json"
        text = source.read_text(encoding="utf-8")
    elif (run_dir / "final.npz").is_file():
        source = run_dir / "final.npz"
        with np.load(source) as data:
            text = str(data["scene"])
    else:
        raise SceneError(f"{run_dir}: no scene.json or final.npz, so no scene to render; is it a `sphcore run` folder?")
    scene = Scene.from_dict(json.loads(text), str(source))
    if scene.dim != 3:
        raise SceneError(f"{run_dir}: {scene['name']} is a 2D run; `sphcore render` draws 3D surfaces, "
                         f"use `sphcore plot {run_dir}` for 2D")

    def step(path):
        m = re.search(r"_(\d+)\.vtp$", path.name)
        return int(m.group(1)) if m else -1

    pvd = run_dir / f"{scene['name']}.pvd"
    if pvd.is_file():
        files = [run_dir / ds.get("file", "") for ds in ET.parse(pvd).getroot().iter("DataSet")]
    else:
        files = list(run_dir.glob(f"{scene['name']}_*.vtp"))
    files = sorted({f for f in files if f.is_file() and step(f) >= 0}, key=step)
    if not files:
        raise SceneError(f"{run_dir}: no snapshots ({scene['name']}_<step>.vtp) to render")
    return scene, files


def render_run(run_dir, out_dir, backend="numba", spacing=None, level=0.5, particles=False, every=1,
               mesh_format="vtp", progress=True):
    """Surface mesh and picture of every `every`-th snapshot of a 3D run: out_dir/<snapshot>.png
    and .vtp or .ply (points, triangles wound outwards, point normals "Normals"), from one camera
    fixed by the scene's box. `spacing` (default h / 2) and `level` go to particle_surface.
    Returns the paths written, in order."""
    import pyvista as pv
    from tqdm import tqdm

    from sphcore.surface import particle_surface

    if mesh_format not in ("vtp", "ply"):
        raise ValueError(f"mesh_format must be vtp or ply, got {mesh_format!r}")
    if every < 1:
        raise ValueError(f"every must be >= 1, got {every}")
    scene, snapshots = load_run(run_dir)
    times = snapshot_times(Path(run_dir) / f"{scene['name']}.pvd")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    box = (np.array(scene["domain.box_min"], float), np.array(scene["domain.box_max"], float))
    gravity = np.array(scene["forces.gravity"], float) if scene["physics.gravity"] else np.zeros(3)
    up = -gravity / np.linalg.norm(gravity) if np.linalg.norm(gravity) > 0 else (0.0, 1.0, 0.0)
    window = (1024, 768)
    camera = box_camera(*box, up=up, aspect=window[0] / window[1])
    written = []
    for path in tqdm(snapshots[::every], unit="frame", disable=not progress, desc=f"render {scene['name']}"):
        position = np.asarray(pv.read(path).points, np.float32)
        if len(position):
            verts, faces, normals = particle_surface(scene, position, spacing=spacing, level=level, backend=backend)
        else:  # no fluid left: an empty mesh and a picture of the box
            verts, faces, normals = np.zeros((0, 3), np.float32), np.zeros((0, 3), np.int32), np.zeros((0, 3), np.float32)
        mesh = surface_mesh(verts, faces, normals)
        written.append(replace_into(out_dir / f"{path.stem}.{mesh_format}", lambda tmp: mesh.save(str(tmp))))
        t = times.get(path.name)
        text = f"{scene['name']}  t = {t:.4g} s" if t is not None else f"{scene['name']}  {path.stem}"
        written.append(render_mesh(verts, faces, normals, out_dir / f"{path.stem}.png",
                                   particles=position if particles else None, box=box, camera=camera,
                                   window_size=window, text=text))
    return written


def snapshot_times(pvd):
    """file name -> time, from a .pvd ({} if there is none)."""
    if not Path(pvd).is_file():
        return {}
    return {ds.get("file"): float(ds.get("timestep", "nan")) for ds in ET.parse(pvd).getroot().iter("DataSet")}
