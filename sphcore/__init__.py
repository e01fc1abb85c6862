"""sphcore: SPH written once as GLSL compute shaders, run by Vulkan or by their numba mirrors."""
__version__ = "0.1.0"
