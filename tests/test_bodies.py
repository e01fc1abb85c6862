"""Bodies (issue 33): the wall particles of Adami, Hu & Adams 2012 (shaders/sph/wall_pressure.comp) against their
formula, the fluid's force on a tank at rest against the water's weight, no particle through a thin plate or past
a sharp corner, and what a run writes."""
import json

import numpy as np
import pytest

from conftest import vulkan_or_skip

from sphcore import geometry
from sphcore.runner import run
from sphcore.paths import SCENE_DIR
from sphcore.scene import Scene, SceneError
from sphcore.simulation import Simulation

# a square tank from a polygon (fluid inside), inside the box and more than h from its walls (no mirror images)
TANK = {"physics": {"model": "engineering"},
        "domain": {"box_min": [0.0, 0.0], "box_max": [1.0, 1.0]},
        "fluid": {"spacing": 0.02, "blocks": [{"min": [0.2, 0.2], "max": [0.5, 0.5]}]},
        "bodies": [{"name": "tank", "polygon": [[0.2, 0.2], [0.8, 0.2], [0.8, 0.9], [0.2, 0.9]], "fluid": "inside"}]}


def scene_of(base, **tables):
    """`base` with tables replaced ({"physics": {...}} merged key by key; "bodies" replaced)."""
    data = json.loads(json.dumps(base))
    for table, keys in tables.items():
        if isinstance(keys, dict):
            data.setdefault(table, {}).update(keys)
        else:
            data[table] = keys
    return Scene.from_dict(data)


def kernel_shape(r, h):
    """Wendland C2's shape (1 - q)^4 (1 + 4 q), q = r / h: Adami's sums are ratios, its normalisation cancels."""
    q = np.minimum(r / h, 1.0)
    return (1 - q) ** 4 * (1 + 4 * q)


@pytest.mark.parametrize("wall_model", ["free_slip", "no_slip"])
def test_wall_pressure_is_adamis(wall_model):
    """After a tenth of a second of a dam break in the tank, each wall particle's pressure, density and velocity
    are Adami's eq. 27 and 22 over the fluid within h (float64, all pairs): the fluid's Shepard-weighted pressure
    plus the hydrostatic rho_f g . r_wf, the density of that pressure, and (no slip) minus the weighted velocity."""
    scene = scene_of(TANK, domain={"wall_model": wall_model})
    with Simulation(scene, "numba") as sim:
        sim.step(60)
        sim.compute_densities()  # (the walls from the fluid as it is now)
        fluid, walls = sim.read(), sim.walls
    xf, xw = fluid["particle_x"].astype(np.float64), walls["particle_x"].astype(np.float64)
    r = xw[:, None, :] - xf[None, :, :]
    w = kernel_shape(np.sqrt((r ** 2).sum(-1)), scene.h)
    total = w.sum(1)
    wet = total > 0
    assert wet.sum() > 50
    g = np.array(scene["forces.gravity"])
    p = (w @ fluid["particle_p"] + np.einsum("wfd,f,wf,d->w", r, fluid["particle_rho"], w, g))[wet] / total[wet]
    scale = np.abs(p).max()
    assert np.abs(walls["particle_p"][wet] - p).max() < 1e-4 * scale
    assert np.all(walls["particle_p"][~wet] == 0)
    rho = scene["fluid.rest_density"] + walls["particle_p"] / scene["fluid.stiffness"]  # (linear law's inverse)
    assert np.allclose(walls["particle_rho"], rho, rtol=1e-6)
    v = -(w @ fluid["particle_v"])[wet] / total[wet, None] if wall_model == "no_slip" else 0 * xw[wet]
    assert np.abs(walls["particle_v"][wet] - v).max() < 1e-4 * np.abs(fluid["particle_v"]).max()


def test_force_on_a_tank_at_rest_is_the_weight():
    """Water at rest in a tank made of three bodies: the fluid's force on the floor, averaged over the second half
    of a second, is the water's weight within 1 %, on each side wall rho g H^2 / 2 (per metre) within 3 %, and no
    particle leaves the tank."""
    depth, dx, rho0, g = 0.3, 0.015, 1000.0, 9.81
    scene = scene_of(TANK, fluid={"spacing": dx, "blocks": [{"min": [0.2, 0.2], "max": [0.8, 0.2 + depth]}]},
                     bodies=[{"name": "floor", "polygon": [[0.0, 0.0], [1.0, 0.0], [1.0, 0.2], [0.0, 0.2]]},
                             {"name": "left", "polygon": [[0.0, 0.2], [0.2, 0.2], [0.2, 0.9], [0.0, 0.9]]},
                             {"name": "right", "polygon": [[0.8, 0.2], [1.0, 0.2], [1.0, 0.9], [0.8, 0.9]]}])
    forces = []
    with Simulation(scene, "numba") as sim:
        while sim.time < 1.0:
            sim.step(25)
            if sim.time > 0.5:
                fluid, walls = sim.read(), sim.walls
                forces.append([scene.mass * walls["particle_a"][walls["body"] == k].sum(0) for k in range(3)])
    floor, left, right = np.mean(forces, axis=0)
    n = len(fluid["particle_x"])
    weight = scene.mass * n * g
    height = n * scene.mass / rho0 / 0.6  # the water's incompressible height
    side = rho0 * g * height ** 2 / 2
    assert abs(floor[1] + weight) < 0.01 * weight  # (the force on the floor points down)
    assert abs(left[0] + side) < 0.03 * side and abs(right[0] - side) < 0.03 * side
    x = fluid["particle_x"]
    assert x[:, 0].min() > 0.2 and x[:, 0].max() < 0.8 and x[:, 1].min() > 0.2


def test_water_at_rest_on_a_floor_of_wall_particles_does_not_sink():
    """Molteni's density diffusion over a fluid particle at a floor of wall particles: the walls take part with their
    extrapolated densities, so the bottom row's density rate at rest is that of the bulk (measured 0.4 kg/m^3/s; with
    the walls left out of the diffusion it was -60, and the row sank 0.06 dx in half a second, a 3D cylinder's
    water through its floor by 1.5 s), and the bottom row stays where it started within 0.02 dx (measured 0.004)."""
    dx = 0.02
    scene = scene_of(TANK, fluid={"spacing": dx, "blocks": [{"min": [0.2, 0.2], "max": [0.8, 0.5]}]})
    with Simulation(scene, "numba") as sim:
        x0 = sim.read()["particle_x"]
        bottom = x0[:, 1] < x0[:, 1].min() + dx / 2
        sim.step(1)  # (the walls' densities from the fluid's at the start)
        assert abs(sim.read()["particle_drho"][bottom].mean()) < 5.0
        while sim.time < 0.5:
            sim.step(50)
        sink = (x0[bottom, 1] - sim.read()["particle_x"][bottom, 1]).mean()
    assert sink < 0.02 * dx, f"the bottom row sank {sink / dx:.3f} dx"


@pytest.mark.parametrize("shape", ["thin_plate", "sharp_corner"])
def test_no_particle_enters_a_body(shape):
    """A dam break hits a plate as thin as the wall layer (h), or a wedge with a 20-degree tip pointing into the
    flow: no fluid particle reaches the body's first layer of wall particles, half a spacing inside its surface, so
    none gets through (measured: the deepest 0.33 dx, in the plate at the impact)."""
    dx = 0.01
    h = 4 * dx
    obstacle = ([[0.5, 0.0], [0.5 + h, 0.0], [0.5 + h, 0.3], [0.5, 0.3]] if shape == "thin_plate" else
                [[0.45, 0.0], [0.7, 0.0], [0.7, 0.09]])  # (tan 20 deg = 0.36: 0.09 over 0.25)
    scene = scene_of(TANK, fluid={"spacing": dx, "blocks": [{"min": [0.0, 0.0], "max": [0.25, 0.3]}]},
                     domain={"box_max": [1.0, 0.6]}, bodies=[{"name": shape, "polygon": obstacle}])
    with Simulation(scene, "numba") as sim:
        closest = np.inf
        for _ in range(8):
            sim.step(60)
            x = sim.read()["particle_x"]
            closest = min(closest, float(geometry.signed_distance(scene.bodies[0], x).min()))
    assert closest > -0.5 * dx, f"a particle {-closest / dx:.2f} dx inside the {shape}"


def test_a_run_writes_the_walls_once_and_the_fluid_alone(tmp_path):
    """walls.vtp holds the wall particles with their body's index; snapshots and final.npz hold the fluid only."""
    scene = scene_of(TANK)
    final = run(scene, steps=10, out_dir=tmp_path, progress=False)
    fluid = len(scene.initial_positions())
    walls, body = scene.wall_positions()
    assert final["position"].shape == (fluid, 2)
    text = (tmp_path / "walls.vtp").read_bytes()
    assert f'NumberOfPoints="{len(walls)}"'.encode() in text and b'Name="body"' in text
    assert f'NumberOfPoints="{fluid}"'.encode() in (tmp_path / "scene_0000010.vtp").read_bytes()


@pytest.mark.vulkan
def test_gauges_on_a_body_write_the_same_bytes_on_both_backends(tmp_path):
    """A tank at rest with a force, a pressure and a height gauge: numba and lavapipe write the same CSV bytes, and
    the force on the tank is the water's weight: each sample within 5 % (the column rings, as a weakly compressible
    one does), their mean within 1 %."""
    vulkan_or_skip()
    gauges = [{"name": "force", "quantity": "force", "body": "tank", "interval": 0.005},
              {"name": "p", "quantity": "pressure", "at": [0.5, 0.23], "interval": 0.005},
              {"name": "h", "quantity": "height", "at": [0.5, 0.21], "interval": 0.005}]
    scene = scene_of(TANK, fluid={"blocks": [{"min": [0.2, 0.2], "max": [0.8, 0.5]}]}, gauges=gauges)
    for backend in ("numba", "vulkan"):
        run(scene, backend=backend, steps=60, out_dir=tmp_path / backend, progress=False)
    for gauge in gauges:
        name = f"gauges/{gauge['name']}.csv"
        assert (tmp_path / "numba" / name).read_bytes() == (tmp_path / "vulkan" / name).read_bytes(), name
    rows = np.loadtxt(tmp_path / "numba" / "gauges/force.csv", delimiter=",", skiprows=1, ndmin=2)
    weight = scene.mass * scene.fluid_count() * 9.81
    assert len(rows) >= 10 and np.all(np.abs(rows[:, 2] + weight) < 0.05 * weight)
    assert abs(rows[:, 2].mean() + weight) < 0.01 * weight


def test_a_mesh_given_as_a_scene_is_named_so():
    """`sphcore run wedge.stl` says the file is a mesh for a scene's [[bodies]], not "malformed TOML"."""
    with pytest.raises(SceneError, match=r"wedge\.stl: a mesh, not a scene: name it in a scene's \[\[bodies\]\]"):
        Scene.load(SCENE_DIR / "meshes" / "wedge.stl")


def test_a_particle_through_the_first_wall_layer_is_found():
    """geometry.buried (the health check's test for a leaked wall): none of the fluid at the start, not a point on the
    tank's first layer of wall particles, yes a point a spacing deeper, inside the floor."""
    scene = scene_of(TANK)
    dx, lo, hi = scene["fluid.spacing"], scene["domain.box_min"], scene["domain.box_max"]
    keys = geometry.buried_keys(scene.wall_positions()[0], lo, hi, dx)
    assert not geometry.buried(keys, scene.initial_positions(), lo, hi, dx).any()
    first, deeper = [0.5, 0.2 - dx / 2], [0.5, 0.2 - 1.6 * dx]
    assert geometry.buried(keys, np.array([first, deeper]), lo, hi, dx).tolist() == [False, True]
