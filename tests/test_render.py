"""`sphcore render`: pictures of a surface (offscreen, pyvista) and the command end to end."""
import json
import math
import xml.etree.ElementTree as ET

import numpy as np
import pytest

pv = pytest.importorskip("pyvista")

from sphcore.cli import SCENE_DIR, main  # noqa: E402
from sphcore.render import BACKGROUND, read_positions, render_mesh, render_run  # noqa: E402
from sphcore.scene import Scene, SceneError  # noqa: E402
from sphcore.surface import marching_cubes  # noqa: E402

W, H = 400, 300
RADIUS, DISTANCE = 0.5, 3.0  # the sphere, and the camera's distance from its centre (on the z axis)


def read_png(path):
    from PIL import Image
    return np.asarray(Image.open(path).convert("RGB")).astype(int)


def foreground(img):
    background = np.round(np.array(pv.Color(BACKGROUND).float_rgb) * 255).astype(int)
    return np.any(img != background, axis=-1)


def sphere_mesh(n=40):
    """verts, faces, normals of the sphere |x| = RADIUS centred at 0: the isosurface c = 0.5 of
    c = 1 - |x| (high inside, like the colour field, so the normals point outwards)."""
    x = np.linspace(-1.0, 1.0, n)
    X, Y, Z = np.meshgrid(x, x, x, indexing="ij")
    volume = (1.0 - np.sqrt(X**2 + Y**2 + Z**2)).astype(np.float32)
    d = x[1] - x[0]
    verts, faces, normals = marching_cubes(volume, 1.0 - RADIUS, spacing=(d, d, d))
    return verts - 1.0, faces, normals


def render_sphere(tmp_path, normals_sign=1.0):
    verts, faces, normals = sphere_mesh()
    assert len(faces) > 1000
    # outward normals: at every vertex the normal is along the position
    assert np.mean(np.sum(normals * verts, axis=1) > 0) == 1.0
    png = tmp_path / "sphere.png"
    out = render_mesh(verts, faces, normals_sign * normals, png, camera=((0, 0, DISTANCE), (0, 0, 0), (0, 1, 0)),
                      window_size=(W, H))
    assert out == png and png.is_file()
    assert not list(tmp_path.glob(".*tmp*"))  # written through a temporary name, then renamed
    return read_png(png)


def test_sphere_picture(tmp_path):
    img = render_sphere(tmp_path)
    assert img.shape == (H, W, 3)
    fg = foreground(img)
    # The sphere seen from distance D subtends a half-angle asin(r / D); with a vertical view angle
    # of 30 degrees its outline is a disc of radius tan(asin(r / D)) / tan(15 deg) * H / 2 pixels:
    # 94.6 px, a fraction pi R^2 / (W H) = 0.234 of the image. The mesh is a polyhedron inscribed
    # in the sphere (its vertices on it, its faces within a sample spacing, 0.05, of it: radius
    # 0.5, so up to ~2 % less in radius and ~4 % in area; much less on average), and the edge is
    # antialiased (one pixel ring of 2 pi R = 600 px, 2 % of the disc's 28,000 px): the fraction
    # lies within [0.90, 1.05] of the disc's.
    radius_px = math.tan(math.asin(RADIUS / DISTANCE)) / math.tan(math.radians(15)) * H / 2
    disc = math.pi * radius_px**2 / (W * H)
    assert 0.90 * disc <= fg.mean() <= 1.05 * disc, (fg.mean(), disc)
    assert fg[H // 2, W // 2]  # the centre is the sphere
    for y, x in ((0, 0), (0, W - 1), (H - 1, 0), (H - 1, W - 1)):
        assert not fg[y, x]
    # centred: the foreground's centroid within 2 px of the image centre
    ys, xs = np.nonzero(fg)
    assert abs(xs.mean() - (W - 1) / 2) < 2 and abs(ys.mean() - (H - 1) / 2) < 2
    # lit, not flat: a wide spread of intensities over the disc (a flat colour would give one value)
    inner = fg & (np.hypot(*np.mgrid[:H, :W] - np.array([(H - 1) / 2, (W - 1) / 2])[:, None, None]) < 0.9 * radius_px)
    grey = img.sum(axis=-1)[inner] / 3
    assert np.percentile(grey, 95) - np.percentile(grey, 5) > 40, np.percentile(grey, [5, 50, 95])
    # lit from above left of the camera: the upper left quarter of the disc is brighter than the
    # lower right; with the normals pointing into the sphere this fails (the key light would
    # light the far side)
    cy, cx = (H - 1) / 2, (W - 1) / 2
    yy, xx = np.mgrid[:H, :W]
    upper_left = inner & (yy < cy) & (xx < cx)
    lower_right = inner & (yy > cy) & (xx > cx)
    brightness = img.sum(axis=-1)
    assert brightness[upper_left].mean() > brightness[lower_right].mean() + 30


def test_sphere_inward_normals_light_wrongly(tmp_path):
    """The check above can fail: the same mesh with its normals flipped is lit from behind."""
    img = render_sphere(tmp_path, normals_sign=-1.0)
    fg = foreground(img)
    yy, xx = np.mgrid[:H, :W]
    brightness = img.sum(axis=-1)
    upper_left = fg & (yy < H / 2) & (xx < W / 2)
    lower_right = fg & (yy > H / 2) & (xx > W / 2)
    assert not brightness[upper_left].mean() > brightness[lower_right].mean() + 30


def test_empty_surface_draws_the_box(tmp_path):
    empty = np.zeros((0, 3), np.float32)
    png = render_mesh(empty, empty.astype(np.int32), empty, tmp_path / "empty.png",
                      box=((0, 0, 0), (1, 0.5, 0.3)), window_size=(W, H))
    fg = foreground(read_png(png))
    assert 0 < fg.mean() < 0.05  # the outline's lines only


def run_cli(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    assert code == 0, err
    return out


@pytest.fixture(scope="module")
def droplet_run(tmp_path_factory):
    """droplet_3d for 2 steps: snapshots at steps 0 and 2 (output_every = 250 > 2, and the end)."""
    out = tmp_path_factory.mktemp("droplet")
    assert main(["run", "droplet_3d", "--steps", "2", "--out", str(out)]) == 0
    return out


def check_meshes(paths, scene):
    lo = np.array(scene["domain.box_min"]) - scene.h
    hi = np.array(scene["domain.box_max"]) + scene.h
    for path in paths:
        mesh = pv.read(path)
        assert mesh.n_cells > 0 and mesh.is_all_triangles, path
        assert np.all((mesh.points >= lo) & (mesh.points <= hi)), path
        normals = mesh.point_data["Normals"]
        assert normals.shape == (mesh.n_points, 3)
        assert np.allclose(np.linalg.norm(normals, axis=1), 1, atol=1e-3)
        # the droplet is one closed blob: the normals point away from its centre, and the
        # faces are wound outwards too (their right-hand normals agree with the vertex normals)
        centre = mesh.points.mean(axis=0)
        assert np.mean(np.sum(normals * (mesh.points - centre), axis=1) > 0) > 0.99
        faces = mesh.regular_faces
        a, b, c = (mesh.points[faces[:, k]] for k in range(3))
        assert np.mean(np.sum(np.cross(b - a, c - a) * normals[faces].sum(axis=1), axis=1) > 0) > 0.99


def test_render_cli(droplet_run, tmp_path, capsys):
    run = droplet_run
    pvd = ET.parse(run / "droplet_3d.pvd").getroot()
    stems = [ds.get("file")[:-4] for ds in pvd.iter("DataSet")]
    assert stems == ["droplet_3d_0000000", "droplet_3d_0000002"]
    times = [float(ds.get("timestep")) for ds in pvd.iter("DataSet")]
    surfaces = ["droplet_3d_surface_0000000", "droplet_3d_surface_0000002"]
    scene = Scene.from_dict(json.loads((run / "scene.json").read_text()))

    out = run_cli(capsys, "render", run, "--out", run / "frames")
    assert "2 frames" in out and len(out.strip().splitlines()) == 1
    frames = run / "frames"
    assert sorted(p.name for p in frames.iterdir()) == sorted(
        [f"{s}.png" for s in surfaces] + [f"{s}.vtp" for s in surfaces] + ["droplet_3d_surface.pvd"])
    check_meshes([frames / f"{s}.vtp" for s in surfaces], scene)
    # the meshes' series gives ParaView each mesh's time: its snapshot's, from the run's .pvd
    series = ET.parse(frames / "droplet_3d_surface.pvd").getroot()
    assert [(ds.get("file"), float(ds.get("timestep"))) for ds in series.iter("DataSet")] == [
        (f"{s}.vtp", t) for s, t in zip(surfaces, times)]
    assert times[1] > times[0]
    for s in surfaces:
        img = read_png(frames / f"{s}.png")
        assert img.shape == (768, 1024, 3)
        fg = foreground(img)
        assert 0.01 < fg.mean() < 0.5
    # the camera is fixed: two frames of an (almost) unchanged droplet are (almost) the same picture
    a, b = (foreground(read_png(frames / f"{s}.png")) for s in surfaces)
    assert np.mean(a != b) < 0.01

    # ply, every 2nd snapshot, particles drawn; no .pvd (ParaView's series reader takes VTK XML files)
    run_cli(capsys, "render", run, "--out", tmp_path / "ply", "--format", "ply", "--every", "2", "--particles")
    assert sorted(p.name for p in (tmp_path / "ply").iterdir()) == [f"{surfaces[0]}.ply", f"{surfaces[0]}.png"]
    check_meshes([tmp_path / "ply" / f"{surfaces[0]}.ply"], scene)


def test_render_into_the_run_folder_leaves_the_run_alone(droplet_run, tmp_path):
    """The meshes' names are never the run's (NAME_NNNNNNN.vtp, NAME.pvd): rendered into a copy of the
    run's folder, every file of the run keeps its bytes."""
    import shutil
    run = tmp_path / "run"
    shutil.copytree(droplet_run, run, ignore=shutil.ignore_patterns("frames"))
    before = {p.name: p.read_bytes() for p in run.iterdir()}
    written = render_run(run, run, every=2, progress=False)
    assert [p.name for p in written] == ["droplet_3d_surface_0000000.vtp", "droplet_3d_surface_0000000.png",
                                         "droplet_3d_surface.pvd"]
    assert {p.name: p.read_bytes() for p in run.iterdir() if p.name in before} == before
    assert pv.read(run / "droplet_3d_0000000.vtp").n_verts == pv.read(run / "droplet_3d_0000000.vtp").n_points > 0
    # without the run's .pvd the snapshots are found by name, the meshes beside them not taken for
    # snapshots; no times, so no series of the meshes
    (run / "droplet_3d.pvd").unlink()
    written = render_run(run, tmp_path / "again", progress=False)
    assert [p.name for p in written] == ["droplet_3d_surface_0000000.vtp", "droplet_3d_surface_0000000.png",
                                         "droplet_3d_surface_0000002.vtp", "droplet_3d_surface_0000002.png"]


def test_render_refuses_an_out_holding_a_run_of_those_names(droplet_run, tmp_path):
    """An --out holding a run named droplet_3d_surface, whose snapshots and series are named as the
    droplet's meshes are: refused in one line naming the folder and a name, before anything is written."""
    other = tmp_path / "other"
    other.mkdir()
    (other / "scene.json").write_text(json.dumps({**json.loads((droplet_run / "scene.json").read_text()),
                                                  "name": "droplet_3d_surface"}))
    (other / "droplet_3d_surface_0000000.vtp").write_bytes(b"the other run's snapshot")
    with pytest.raises(SceneError, match=r"other: holds a run .*droplet_3d_surface.*give another --out") as e:
        render_run(droplet_run, other, progress=False)
    assert "\n" not in str(e.value)
    assert sorted(p.name for p in other.iterdir()) == ["droplet_3d_surface_0000000.vtp", "scene.json"]
    assert (other / "droplet_3d_surface_0000000.vtp").read_bytes() == b"the other run's snapshot"


def test_render_run_empty_surface(droplet_run, tmp_path):
    """A level the colour field never reaches: empty meshes and pictures of the box, no crash."""
    written = render_run(droplet_run, tmp_path, level=10.0, every=2, progress=False)
    assert [p.name for p in written] == ["droplet_3d_surface_0000000.vtp", "droplet_3d_surface_0000000.png",
                                         "droplet_3d_surface.pvd"]
    assert pv.read(written[0]).n_points == 0
    assert 0 < foreground(read_png(written[1])).mean() < 0.05


def test_render_draws_the_bodies_wall_particles(droplet_run, tmp_path):
    """A run's walls.vtp (as `sphcore run` writes it for bodies) is drawn in grey where its points are,
    in every picture; without it the picture has no grey there."""
    import shutil

    from sphcore.output import vtp_bytes

    run = tmp_path / "run"
    shutil.copytree(droplet_run, run, ignore=shutil.ignore_patterns("frames"))
    plain = foreground(read_png(render_run(run, tmp_path / "plain", every=2, progress=False)[1]))
    # a block of 5 x 5 x 5 points at spacing 0.01 in the box's corner x, y low and z high, clear of the droplet
    g = (np.arange(5) + 0.5) * 0.01
    block = np.array([[x, y, 0.25 + z] for x in g for y in g for z in g], np.float32)
    (run / "walls.vtp").write_bytes(vtp_bytes(block, {"body": np.zeros(len(block), np.int32)}))
    img = read_png(render_run(run, tmp_path / "walls", every=2, progress=False)[1])
    drawn = foreground(img) & ~plain
    grey = np.ptp(img, axis=-1) < 12  # r, g and b alike: not the water's blue
    assert drawn.sum() > 500 and grey[drawn].mean() > 0.95, (drawn.sum(), grey[drawn].mean())
    assert not np.any(foreground(img) & ~drawn & ~plain)
    # where the block is: its centre projected by the render's camera
    x, y = project(block.mean(axis=0), (0, 0, 0), (0.3, 0.3, 0.3))
    ys, xs = np.nonzero(drawn)
    assert abs(xs.mean() - x) < 10 and abs(ys.mean() - y) < 10


def test_render_draws_the_pier_of_the_shipped_scene(tmp_path, capsys):
    """dam_break_obstacle_3d run for 2 steps: the run writes its pier's wall particles, and the picture shows
    them in grey around the pier's axis (below the water's top, the column is far from it)."""
    run = tmp_path / "run"
    run_cli(capsys, "run", "dam_break_obstacle_3d", "--steps", "2", "--out", run)
    scene = Scene.load("dam_break_obstacle_3d")
    assert len(read_positions(run / "walls.vtp")) == len(scene.wall_positions()[0])
    run_cli(capsys, "render", run, "--out", tmp_path / "frames", "--every", "2")
    img = read_png(tmp_path / "frames" / "dam_break_obstacle_3d_surface_0000000.png")
    grey = foreground(img) & (np.ptp(img, axis=-1) < 12) & (img.mean(axis=-1) > 100)  # not the outline's dark grey
    top, foot = (project((0.6, y, 0.15), scene["domain.box_min"], scene["domain.box_max"]) for y in (0.3, 0.0))
    ys, xs = np.nonzero(grey)
    assert len(xs) > 2000
    assert abs(np.median(xs) - (top[0] + foot[0]) / 2) < 20 and top[1] - 20 < np.median(ys) < foot[1] + 20


def project(point, box_min, box_max, size=(1024, 768)):
    """Pixel (x, y) of `point` in render_run's pictures: the pinhole of box_camera's view, 30 degrees vertical."""
    from sphcore.render import box_camera
    position, focal, up = (np.array(v) for v in box_camera(box_min, box_max, aspect=size[0] / size[1]))
    d = (position - focal) / np.linalg.norm(position - focal)
    right = np.cross(-d, up) / np.linalg.norm(np.cross(-d, up))
    v = np.asarray(point, float) - position
    scale = size[1] / 2 / math.tan(math.radians(15)) / (v @ -d)
    return (size[0] - 1) / 2 + scale * (v @ right), (size[1] - 1) / 2 - scale * (v @ up)


def error_line(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    assert code == 1 and out == ""
    assert err.startswith("sphcore: error: ") and len(err.strip().splitlines()) == 1, err
    return err


def test_render_errors(droplet_run, tmp_path, capsys):
    err = error_line(capsys, "render", tmp_path / "missing")
    assert "no such run folder" in err
    # a 2D run: its scene, as `sphcore run` writes it
    run2d = tmp_path / "run2d"
    run2d.mkdir()
    (run2d / "scene.json").write_text(Scene.load(SCENE_DIR / "dam_break_2d.toml").to_json())
    err = error_line(capsys, "render", run2d)
    assert "2D" in err and "sphcore plot" in err
    # a scene but no snapshots
    bare = tmp_path / "bare"
    bare.mkdir()
    (bare / "scene.json").write_text((droplet_run / "scene.json").read_text())
    assert "no snapshots" in error_line(capsys, "render", bare)
    # no scene
    empty = tmp_path / "empty"
    empty.mkdir()
    assert "no scene.json" in error_line(capsys, "render", empty)


def test_render_damaged_inputs_name_the_file(droplet_run, tmp_path, capsys):
    """A truncated final.npz (the only scene), one of random bytes, a truncated snapshot, a truncated
    .pvd: each a one-line error naming the file, and no output written."""
    import shutil
    only_final = tmp_path / "only_final"
    only_final.mkdir()
    np.savez(only_final / "whole.npz", scene=np.array((droplet_run / "scene.json").read_text()),
             x=np.zeros((1000, 3)))
    data = (only_final / "whole.npz").read_bytes()
    (only_final / "whole.npz").unlink()
    (only_final / "final.npz").write_bytes(data[:len(data) // 2])
    err = error_line(capsys, "render", only_final, "--out", tmp_path / "o1")
    assert f"{only_final / 'final.npz'}: not a readable final state" in err
    (only_final / "final.npz").write_bytes(np.random.default_rng(0).bytes(4000))
    err = error_line(capsys, "render", only_final, "--out", tmp_path / "o1")
    assert str(only_final / "final.npz") in err and "allow_pickle" not in err

    run = tmp_path / "run"
    shutil.copytree(droplet_run, run, ignore=shutil.ignore_patterns("frames"))
    snapshot = run / "droplet_3d_0000002.vtp"
    snapshot.write_bytes(snapshot.read_bytes()[:3000])
    err = error_line(capsys, "render", run, "--out", tmp_path / "o2")
    assert f"{snapshot}: not a readable snapshot, truncated" in err
    assert not (tmp_path / "o2").exists()  # found before the first frame was drawn
    snapshot.write_bytes(b"<VTKFile>" + b"\x00" * 100 + b"</VTKFile>")  # complete, but garbage
    with pytest.raises(SceneError, match=f"{snapshot}: not a readable snapshot"):
        read_positions(snapshot)
    snapshot.write_text('<VTKFile type="PolyData" version="1.0"><PolyData><Piece NumberOfPoints="5">'
                        '</Piece></PolyData></VTKFile>')  # well-formed, but no points where it says 5
    with pytest.raises(SceneError, match=f"{snapshot}: not a readable snapshot \\(.*Points") as e:
        read_positions(snapshot)
    assert "\n" not in str(e.value) and "0x" not in str(e.value)  # VTK's first error, without its source line
    pvd = run / "droplet_3d.pvd"
    pvd.write_bytes(pvd.read_bytes()[:100])
    err = error_line(capsys, "render", run, "--out", tmp_path / "o3")
    assert f"{pvd}: not a readable .pvd series" in err
    assert not (tmp_path / "o3").exists()
