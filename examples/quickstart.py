"""sphcore from Python: build a scene, step it, read the state, write snapshots, extract and
render the surface. Run it from anywhere: `python examples/quickstart.py` (writes quickstart/)."""
import sphcore

# A scene: a shipped one by name (sphcore.Scene.load("dam_break_3d")), a .toml file, or a dict
# that names only what differs from the defaults (`sphcore keys` lists them all). physics.model
# picks the model: "graphics" is the fast one; the default, "engineering", the accurate one.
scene = sphcore.Scene.from_dict({
    "name": "quickstart",
    "physics": {"model": "graphics", "dimension": 3, "equation_of_state": "tait"},
    "domain": {"box_min": [0.0, 0.0, 0.0], "box_max": [0.4, 0.25, 0.12]},
    "fluid": {"blocks": [{"min": [0.0, 0.0, 0.0], "max": [0.12, 0.16, 0.12]}],
              "spacing": 0.01, "stiffness": 900.0, "viscosity": 0.5},
    "time": {"dt": "auto"},
})

with sphcore.Simulation(scene, backend="numba") as sim:  # or backend="vulkan"
    for _ in range(4):
        sim.step(100)
        state = sim.read()  # numpy arrays in particle order: particle_x (N, 3), particle_rho (N,), ...
        front = state["particle_x"][:, 0].max()
        print(f"t = {sim.time:.3f} s: front at x = {front:.3f} m, "
              f"density {state['particle_rho'].min():.0f}..{state['particle_rho'].max():.0f} kg/m^3")
        sim.write_snapshot("quickstart")  # quickstart/quickstart_<step>.vtp and quickstart.pvd
    verts, faces, normals = sim.surface()  # marching cubes on the colour field

print(f"surface: {len(verts)} vertices, {len(faces)} triangles")
sphcore.render_mesh(verts, faces, normals, "quickstart/surface.png",
                    box=(scene["domain.box_min"], scene["domain.box_max"]))
