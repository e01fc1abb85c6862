// Compile-time options of the marching-cubes shaders, as specialization constants (ids 9 and 10,
// apart from those of shaders/sph/constants.glsl: 1-8 and 11). Constant 0 is the work-group size.
layout(constant_id = 9) const bool MIDPOINT = false;         // vertices at edge midpoints (else linear interpolation)
layout(constant_id = 10) const bool FORWARD_NORMALS = false; // normals by forward differences (else central)
