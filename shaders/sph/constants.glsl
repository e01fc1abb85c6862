// Compile-time choices of a scene, as specialization constants: a term a scene does not use is
// compiled out. Constant 0 is the work-group size. Scene.spec (sphcore/scene.py) sets these from
// the scene; the numba mirrors receive the same values as closure constants.
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
// Engineering WCSPH (issue 12): each model a small helper in an include, chosen here.
layout(constant_id = 12) const uint KERNEL = 0;           // 0: Mueller et al. 2003 (poly6, spiky, viscosity);
                                                          // 1: Wendland C2 for values and gradients
layout(constant_id = 13) const bool CONTINUITY = false;  // density integrated from d rho/dt (else summation)
layout(constant_id = 14) const uint DENSITY_DIFFUSION = 0; // 0: none, 1: Molteni & Colagrossi 2009,
                                                          // 2: Fourtakas et al. 2019
layout(constant_id = 15) const uint VISCOSITY_MODEL = 0;  // 0: laminar (fluid.viscosity), 1: artificial
                                                          // (Monaghan 1992, coefficient alpha)
layout(constant_id = 16) const bool NO_SLIP = false;      // wall images reverse the whole velocity (else the
                                                          // normal component only: free slip)
layout(constant_id = 17) const bool VERLET = false;       // kick-drift-kick (else symplectic Euler)
layout(constant_id = 18) const bool ADAPTIVE_DT = false;  // dt reduced on the device every step (time_state)
// Incompressible pressure solver (issue 14): DFSPH (Bender & Koschier 2015, 2017), else the state equation.
layout(constant_id = 19) const bool DFSPH = false;        // physics.pressure_solver = "dfsph": dfsph_*.comp solve
                                                          // for the pressure; compute_forces adds no pressure term
layout(constant_id = 20) const uint MAX_NEIGHBOURS = 0;   // DFSPH: slots per particle of its neighbour list
                                                          // (dfsph.glsl; fluid.max_neighbours)
layout(constant_id = 21) const bool GRADIENTS = false;    // DFSPH: dfsph_factor stores each list entry's
                                                          // V grad W for the sweeps (Scene.spec_for: numba),
                                                          // else they compute it again (dfsph.glsl)
layout(constant_id = 22) const bool LIST_BY_PARTICLE = false; // the lists particle-major (Scene.spec_for: numba),
                                                          // else slot-major (dfsph.glsl: list_slot)
layout(constant_id = 24) const bool BRANCH_FREE_SCAN = false; // compute_density lists first, with no branch on
                                                          // the distance (the numba backend times both scans)
layout(constant_id = 25) const bool LIST_CHUNKS = false;  // slot-major lists in chunks of 4 slots (Scene.spec_for:
                                                          // Vulkan's state equation; dfsph.glsl: list_slot)
layout(constant_id = 26) const uint LIST_SKIN = 0;        // the state equation's lists reused between builds: their
                                                          // skin in thousandths of h (physics.list_skin; 0: a list
                                                          // every step; cells.glsl: list_reach)
layout(constant_id = 27) const uint CELL_SPLIT = 1;       // cells per search reach: 1 (a scan tests the 3^dim cells
                                                          // around a particle's) or 2 (the 5^dim of half the side;
                                                          // Scene.cell_split: supports of 2.5 dx or more)
// Particle shifting (issue 31): each term a helper in an include, called from the one neighbour walk (walk.glsl).
layout(constant_id = 28) const uint SHIFTING = 0;         // 0: none, 1: Lind et al. 2012's Fickian shifting
                                                          // (physics.shifting; shifting.glsl)
// Bodies from meshes and polygons (issue 33): Adami et al. 2012's wall particles, the particles whose id is
// P.fluid_count or more (wall_pressure.comp gives them the fluid's pressure and velocity; integrate leaves them).
layout(constant_id = 29) const bool BODIES = false;       // the scene has [[bodies]] (sphcore/geometry.py)
// One run on several ranks (issue 34: sphcore.parallel): a rank holds its own particles and others' near its slab.
layout(constant_id = 30) const bool ID_ORDER = false;     // sort_cells orders a cell's particles by id (else by index):
                                                          // the same order whatever rows a rank holds them in
