"""numba mirrors of shaders/sph/*.comp, one module per shader with the same stem.

Each module's factory `stage(spec, real)` builds the shader's body for the specialization
constants `spec` and the precision `real`: np.float32, or np.float64 for the build with
SPHCORE_FLOAT64 (shaders/sph/real.glsl), so that a `real` local, buffer or literal `real(0.0)`
of the shader is the same type here. Parameter-block fields stay float32 on both sides and
promote to float64 where they meet a float64 value, as GLSL converts float to double.
Stages on integers only (the grid sort) accept `real` and ignore it.
"""
from collections import namedtuple


def named(*functions):
    """An include's helpers, returned by its factory: a tuple whose fields are the functions' names, so that a
    stage takes each by name (`cells(spec, real).near_walls`), never by its place."""
    return namedtuple("Helpers", [f.__name__ for f in functions])(*functions)
