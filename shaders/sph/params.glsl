// Parameter block shared by every shader (SPH and neighbour grid): a uniform buffer written once per
// scene, read as `P.name`, and a push constant of what changes from one dispatch to the next, read as
// `D.name`. The numba mirrors read the same bytes: sphcore/params.py parses both blocks into numpy record
// dtypes (std140 offsets, which for these scalars and 3-vectors are std430's), so the two sides cannot drift.
// A new coefficient is one field here and one line in sphcore/params.py's fold_parameters; the block may
// grow to maxUniformBufferRange (16 KiB on every device). All coefficients are folded on the host; units
// are SI. In 2D the z components are 0 and unused.
layout(std140, binding = 63) uniform Params {
    uint n;               // particle count
    uint fluid_count;     // the fluid's particles, ids 0 .. fluid_count - 1; the wall particles of the bodies
                          // (BODIES) follow, fixed
    float h;              // support radius [m] (every kernel is zero past h)
    float h2;             // h^2 [m^2]
    float density_coef;   // m times W's coefficient (kernels.glsl: m W = density_coef kernel_w); mueller:
                          // W_poly6's, 2D m 4/(pi h^8), 3D m 315/(64 pi h^9)
    float pressure_coef;  // m times |grad W|'s coefficient (m grad_i W_ij = -pressure_coef kernel_gradient
                          // r_hat_ij); mueller: W_spiky's, 2D m 30/(pi h^5), 3D m 45/(pi h^6)
    float viscosity_coef; // mu m L's coefficient (kernels.glsl: kernel_laplacian); mueller: lap W_visc's,
                          // 2D mu m 40/(pi h^5), 3D mu m 45/(pi h^6)
                          // (VISCOSITY_MODEL 1, artificial: alpha c h [m^2/s], viscosity.glsl)
    float cohesion_coef;  // minus kappa times W's coefficient (surface tension by cohesion)
    float rest_density;   // rho_0 [kg/m^3] (2D: kg/m^2)
    float stiffness;      // linear: k in p = k (rho - rho_0); Tait: B in p = B ((rho/rho_0)^7 - 1)
    float dt;             // time step [s]; with ADAPTIVE_DT the largest allowed (the viscous bound)
    float restitution;    // fraction of the normal speed kept on a wall bounce [-]
    float inv_cell;       // 1 / cell size of the neighbour grid [1/m]
    vec3 gravity;         // [m/s^2]
    vec3 box_min;         // walls, and the origin of the neighbour grid [m]
    uint cell_total;      // cells in the grid: grid_dim.x * grid_dim.y * grid_dim.z
    vec3 box_max;         // walls [m]
    uint levels;          // HistoPyramid levels above the base (the last one holds one node: the total)
    uvec3 grid_dim;       // cells per axis (the hash period per axis in an open domain)
    // -- density and kernels (issue 12: physics.kernel, physics.density, physics.density_diffusion)
    float diffusion_coef; // delta-SPH: delta h c_0 times pressure_coef (fluid.density_diffusion; 0: none)
    vec3 hydrostatic;     // rho_0 g / c^2 (c^2 = fluid.stiffness): rho^H_ji = hydrostatic . (x_j - x_i)
                          // (Fourtakas et al. 2019; 0 unless density_diffusion = "fourtakas" and gravity)
    // -- forces, walls and time stepping (issue 12: viscosity_model, wall_model, integrator, dt)
    float cfl_number;     // time.dt = "adaptive": time.dt_fraction * 0.25, dt = cfl_number min(h / (c + |v|max),
                          // sqrt(h / |a|max)), c^2 = k (choose_dt.comp)
    // -- pressure solver (issue 14): fluid.max_density_error, max_divergence_error and max_iterations
    //    reach the shaders in dfsph_state and control (the solver writes them there)
    // -- particle shifting (issue 31: physics.shifting, shifting.glsl)
    float shifting_coef;  // A h_s [m], h_s = h / 2: D = shifting_coef |v_i| dt (Skillen et al. 2013; fluid.shifting)
    float shifting_w;     // 1 / kernel_w(dx^2): Lind et al. 2012's W_ij / W(dx) = kernel_w(r2) shifting_w
    // -- one run on several ranks (issue 34: sphcore.parallel)
    uint owned_first;     // the cells of the rank's slab, owned_first .. owned_end - 1: reduce_dt takes the rows the
    uint owned_end;       // sort gave them (owned_end 0: every particle, as on one rank)
    uint cells_first;     // the cells the grid's cell stages take, cells_first .. cells_end - 1 (cells_end 0: every
    uint cells_end;       // cell): on a rank the layers its particles can be in, and a margin; every other cell is
                          // empty (clear_cells, reduce_cells, cell_offsets, sort_cells)
    float summed_min;     // the rows compute_density takes on a rank (owned_end > 0): those whose coordinate along
    float summed_max;     // the slab axis lies in summed_min .. summed_max (summed.glsl)
} P;

// Per dispatch (push constants: 128 bytes on lavapipe, so only what changes between dispatches).
layout(push_constant) uniform Dispatch {
    uint level;           // HistoPyramid level a reduce_cells dispatch writes (1 = first above the base)
} D;
