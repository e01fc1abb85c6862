"""sphcore: SPH written once as GLSL compute shaders, run by Vulkan or by their numba mirrors."""
__version__ = "0.1.0"


def __getattr__(name):
    """`sphcore.marching_cubes`, imported on first use (it brings numba in)."""
    if name == "marching_cubes":
        from sphcore.surface import marching_cubes
        return marching_cubes
    raise AttributeError(f"module 'sphcore' has no attribute {name!r}")
