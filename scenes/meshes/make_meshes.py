"""Writes the meshes shipped in scenes/meshes/ with trimesh (run from anywhere: `python make_meshes.py`).

- spheric_box.stl: the box obstacle of SPHERIC test 2 (Issa & Violeau 2006; Kleefsman et al. 2005), 0.161 m
  along x, 0.161 m high (y), 0.403 m across (z), at its place in scenes/spheric_test2.toml (domain.obstacles):
  min [0.6635, 0, 0.2985], max [0.8245, 0.161, 0.7015]. A body with translate = 0 stands where the box stood.
- cylinder_tank.stl: a vertical (y up) cylindrical tank, radius 0.3 m, height 0.6 m, its base centred on the
  origin, 48 sides: a container (fluid = "inside").
- wedge.stl: a sloping beach, a right triangular prism 0.6 m long (x), 0.2 m high (y) and 0.4 m wide (z), its
  vertical face at x = 0.6 m and its toe at the origin: an obstacle (fluid = "outside"), slope 1 : 3.
- cylinder_pier.stl: a vertical (y up) circular pier, radius 0.045 m, height 0.3 m, its base centred on the
  origin, 32 sides: the obstacle of scenes/dam_break_obstacle_3d.toml (translated there).
Every mesh is closed (watertight), wound outward; the files are binary STL of a few kB.
"""
from pathlib import Path

import numpy as np
import trimesh

HERE = Path(__file__).resolve().parent


def spheric_box():
    lo, hi = np.array([0.6635, 0.0, 0.2985]), np.array([0.8245, 0.161, 0.7015])
    return trimesh.creation.box(extents=hi - lo, transform=trimesh.transformations.translation_matrix((lo + hi) / 2))


def cylinder_tank(radius=0.3, height=0.6, sections=48):
    mesh = trimesh.creation.cylinder(radius=radius, height=height, sections=sections)  # along z, centred
    mesh.apply_transform(trimesh.transformations.rotation_matrix(-np.pi / 2, [1, 0, 0]))  # z -> y
    mesh.apply_translation([0.0, height / 2, 0.0])
    return mesh


def wedge(length=0.6, height=0.2, width=0.4):
    vertices = np.array([[0, 0, 0], [length, 0, 0], [length, height, 0],
                         [0, 0, width], [length, 0, width], [length, height, width]], float)
    faces = [[0, 2, 1], [3, 4, 5],                    # the ends, z = 0 and z = width
             [0, 1, 4], [0, 4, 3],                    # the floor
             [1, 2, 5], [1, 5, 4],                    # the vertical face
             [0, 3, 5], [0, 5, 2]]                    # the slope
    return trimesh.Trimesh(vertices, faces)


def cylinder_pier(radius=0.045, height=0.3, sections=32):
    return cylinder_tank(radius, height, sections)


def main():
    for name, mesh in (("spheric_box", spheric_box()), ("cylinder_tank", cylinder_tank()), ("wedge", wedge()),
                       ("cylinder_pier", cylinder_pier())):
        assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0, name
        mesh.export(HERE / f"{name}.stl")
        print(f"{name}.stl: {len(mesh.faces)} triangles, volume {mesh.volume:.6g} m^3, bounds {mesh.bounds.tolist()}")


if __name__ == "__main__":
    main()
