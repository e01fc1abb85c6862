"""sphcore: SPH written once as GLSL compute shaders, run by Vulkan or by their numba mirrors.

    import sphcore

    scene = sphcore.Scene.load("dam_break_2d")           # a shipped scene, or a path to a .toml file
    with sphcore.Simulation(scene, backend="numba") as sim:
        sim.step(100)
        state = sim.read()                               # numpy arrays in particle order
        print(sim.time, state["particle_x"].shape, state["particle_rho"].mean())

The public names are imported on first use (numba and Vulkan load only when needed):
Scene, SceneError, Simulation, SimulationError, run, resume, SnapshotSeries, marching_cubes,
particle_surface and render_mesh.
"""
__version__ = "0.1.0"

# public name -> the module that defines it
_PUBLIC = {
    "Scene": "sphcore.scene", "SceneError": "sphcore.errors",
    "Simulation": "sphcore.stepper", "SimulationError": "sphcore.errors",
    "run": "sphcore.runner", "resume": "sphcore.runner",
    "SnapshotSeries": "sphcore.output",
    "marching_cubes": "sphcore.surface", "particle_surface": "sphcore.surface",
    "render_mesh": "sphcore.render",
}
__all__ = sorted(_PUBLIC)


def __getattr__(name):
    """`sphcore.Simulation` and the other public names, imported on first use."""
    if name in _PUBLIC:
        import importlib
        return getattr(importlib.import_module(_PUBLIC[name]), name)
    raise AttributeError(f"module 'sphcore' has no attribute {name!r}")


def __dir__():
    return sorted(list(globals()) + __all__)
