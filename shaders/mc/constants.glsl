// Compile-time options of the marching-cubes shaders, as specialization constants (ids 9, 10 and 23,
// apart from those of shaders/sph/constants.glsl: 1-8 and 11-22). Constant 0 is the work-group size.
layout(constant_id = 9) const bool MIDPOINT = false;         // vertices at edge midpoints (else linear interpolation)
layout(constant_id = 10) const bool FORWARD_NORMALS = false; // normals by forward differences (else central)
layout(constant_id = 23) const uint CUBE_RUN = 1;            // emit_cubes: cubes per invocation, a run along z
