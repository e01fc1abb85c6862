// Compile-time choices of a scene, as specialization constants: a term a scene does not use is
// compiled out. Constant 0 is the work-group size. sphcore/plan.py sets these from the scene
// (`specialization`); the numba mirrors receive the same values as closure constants.
layout(constant_id = 1) const uint DIM = 3;              // 2 or 3
layout(constant_id = 2) const bool GRID = true;          // neighbours from the grid (else all pairs)
layout(constant_id = 3) const bool WALLS = true;         // box walls (else an open domain, cells hashed)
layout(constant_id = 4) const bool TAIT = false;         // Tait equation of state (else linear)
layout(constant_id = 5) const bool VISCOSITY = true;     // Mueller's viscosity term
layout(constant_id = 6) const bool SURFACE_TENSION = false; // cohesion (Becker & Teschner 2007)
layout(constant_id = 7) const bool GRAVITY = true;       // the gravity term
layout(constant_id = 8) const bool NEIGHBOUR_STATS = false; // compute_density records each particle's
                                                         // neighbour count and a fingerprint of the set
layout(constant_id = 11) const uint OBSTACLES = 0;       // box obstacles in obstacle_box (domain.obstacles);
                                                         // 0: the obstacle code is compiled out. (9 and 10
                                                         // are the marching-cubes constants, shaders/mc)
