"""`sphcore validate bodies` (sphcore/validate/bodies.py) at a coarse setting: a rotated tank at rest reads
rho g depth at its gauges within 3 % and keeps its water inside; a tank of three bodies carries the water's weight
on its floor within 1 % and rho g H^2 / 2 on each side wall within 3 %; the inclined column holds the lattice
points of the rotated column; the free surface of a lattice block is its top."""
import json
import math

import numpy as np

from sphcore import geometry
from sphcore.scene import Scene
from sphcore.validate import bodies, dam_break

COARSE = {"spacing": 0.02, "t_end": 0.5}


def test_rotated_tank_reads_hydrostatic_pressure_and_keeps_its_water(tmp_path):
    rows, summary = bodies.run_rotated_tank(COARSE, tmp_path, progress=False)
    assert len(summary["pressure_errors_settled"]) == 3
    assert summary["pressure_error_max"] <= 0.03, summary["pressure_errors_settled"]
    assert summary["closest_to_wall_dx"] > -0.5
    assert json.loads((tmp_path / "rotated_tank.json").read_text())["meets"] == {"pressure": True, "inside": True}
    assert rows[-1]["t"] >= COARSE["t_end"] / 2


def test_tank_of_three_bodies_carries_the_weight_and_the_side_thrust(tmp_path):
    """24 particles per depth (the side walls' deficit falls with dx: 3.9 % at 15 per depth, 3.0 % at 20, 2.0 % at
    30; docs/validation/bodies.md)."""
    _, summary = bodies.run_forces_at_rest({"spacing": 0.0125, "t_end": 0.5}, tmp_path, progress=False)
    e = summary["force_errors_settled"]
    assert abs(e["floor"]) <= 0.01 and abs(e["left"]) <= 0.03 and abs(e["right"]) <= 0.03, e
    assert summary["closest_to_wall_dx"] > -0.5


def test_inclined_column_is_the_rotated_column():
    """Every particle of the inclined dam break's column lies in the column (tank frame: 0 < x' <= a, 0 < y' <= 2a)
    and at least dx / 2 inside the tank; the count is the column's lattice area within a wall row's worth."""
    s = {**bodies.COMMON, **bodies.SETTINGS["inclined_dam_break"], "resolution": 10}
    scene, r, corner = bodies.inclined_scene(s, 30.0)
    a, dx = dam_break.SETTINGS["a"], scene["fluid.spacing"]
    x = scene.initial_positions().astype(np.float64)
    local = (x - corner) @ r
    assert local[:, 0].min() > 0 and local[:, 0].max() <= a + 1e-9
    assert local[:, 1].min() > 0 and local[:, 1].max() <= 2 * a + 1e-9
    assert geometry.signed_distance(scene.bodies[0], x).min() >= 0.5 * dx - 1e-9
    assert abs(len(x) - 2 * a * a / dx ** 2) <= 3 * a / dx
    assert np.allclose(scene["forces.gravity"], [9.81 * math.sin(math.radians(30)), -9.81 * math.cos(math.radians(30))])


def test_fluid_surface_of_a_block_is_its_top():
    """On a lattice block the kernel sum is half a full lattice's at the block's top, midway between the top row
    and the row above it (the lattice is symmetric about that line)."""
    dx = 0.02
    scene = Scene.from_dict({"physics": {"model": "engineering"}, "domain": {"box_min": [0.0, 0.0], "box_max": [1.0, 1.0]},
                             "fluid": {"spacing": dx, "blocks": [{"min": [0.0, 0.0], "max": [1.0, 0.4]}]}})
    x = scene.initial_positions().astype(np.float64)
    assert abs(bodies.fluid_surface(scene, x, [0.5, 0.0]) - 0.4) < 0.05 * dx
