// Compile-time options of the marching-cubes shaders, as specialization constants (ids after
// those of shaders/sph/constants.glsl). Constant 0 is the work-group size.
layout(constant_id = 9) const bool MIDPOINT = false;         // vertices at edge midpoints (else linear interpolation)
layout(constant_id = 10) const bool FORWARD_NORMALS = false; // normals by forward differences (else central)
