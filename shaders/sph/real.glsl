// Precision of the particle buffers (position, velocity, acceleration, density, pressure, the
// sort's scratch copies) and of the arithmetic on them: float32, or float64 where the shader is
// built with -DSPHCORE_FLOAT64 (scene key physics.precision = "float64"; the Vulkan device must
// support shaderFloat64). The parameter block stays float32 (sphcore/params.py parses it); its
// values convert exactly to double where they meet a `real`.
// Mirror: the `real` argument of every sphcore/sph factory (np.float32 or np.float64).
// Included by cells.glsl too (for shaders/mc/sample_field.comp, always float32), so guarded.
#ifndef SPHCORE_REAL_GLSL
#define SPHCORE_REAL_GLSL
#ifdef SPHCORE_FLOAT64
#define real double
#define real3 dvec3
#define real4 dvec4
#else
#define real float
#define real3 vec3
#define real4 vec4
#endif
#endif
