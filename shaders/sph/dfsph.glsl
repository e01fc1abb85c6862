// DFSPH, the divergence-free SPH pressure solver (Bender & Koschier 2015, 2017; physics.pressure_solver =
// "dfsph", specialization constant DFSPH): the layout of its state buffers, shared by dfsph_factor.comp,
// dfsph_residual.comp (with dfsph_check.glsl) and dfsph_velocity.comp.
// Mirror: sphcore/sph/dfsph.py (same names, same values).
//
// One time step (sphcore.backends.plan; Bender & Koschier 2017, Alg. 2; the order of SPlisHSPlasH's
// TimeStepDFSPH::step):
//   [grid sort] compute_density (summation) -> dfsph_factor (alpha_i) -> divergence-free solve (solve 1)
//   -> compute_forces (no pressure term) -> reduce_dt, choose_dt (CFL on the particle speed)
//   -> constant-density solve (solve 2) -> integrate (v += dt a, x += dt v).
// A solve is dfsph_residual, then max_iterations times [dfsph_velocity, dfsph_residual], all recorded into
// the command buffer (no readback). The positions do not move from compute_density to integrate, so
// compute_density's scan of the grid cells also writes each particle's neighbour list: its
// neighbours and their wall and obstacle images within h, in the scan's order, as j | image << IMAGE_SHIFT
// in neighbours[list_slot(i, slot)] (slot < MAX_NEIGHBOURS: on Vulkan consecutive invocations read consecutive
// words, or chunks of 4), their number in neighbour_count[i]. dfsph_factor, every sweep of the solves and
// compute_forces walk that list (neighbour_list.glsl: listed_pair): the sums
// run in the scan's order, with the same terms, over about a third (2D) or a seventh (3D) of the candidates.
// The sweeps use each entry's g = V grad_i W_ij as dfsph_factor computes it (listed_gradient): with the
// specialization constant GRADIENTS (numba) the factor stores it in neighbour_gradients[list_slot(i, slot)] and the
// sweeps read it; else they compute it again. The same bits either way on numba and lavapipe (the NVIDIA
// driver, which fuses multiply-adds where it likes, gives the two ways different last bits).
// A particle with more than MAX_NEIGHBOURS sets CONTROL_OVERFLOW_STEP; the host stops the run there
// (sphcore.pressure_solver), as a cut list would silently lose pairs. The stage's solve is D.level
// (1 or 2; for reduce_cells D.level is a pyramid level). The mean residual is reduced in a fixed order
// in two levels: each dfsph_residual work group sums its residuals in order (dfsph_partial), and the
// last of its work groups to finish (an atomic count, CONTROL_FINISHED) sums those (dfsph_check.glsl).
// Once the mean is under the tolerance (after the minimum iterations) or the budget is spent, it sets the
// solve's done flag and zeroes its group counts: the solve's later stages are indirect dispatches
// (vkCmdDispatchIndirect) that read those counts, so the rest of the recorded budget dispatches no work
// groups. dfsph_factor sets the counts at the start of every step. The check has no dispatch of its own:
// an iteration is two dispatches, and a spent one costs two empty dispatches and their barriers (a
// separate check stage made it three).
// Windows (the Vulkan host, where the device has conditional rendering): instead of the whole budget the
// host records a window of W iterations per solve (CONTROL_WINDOW), sized from the last steps' counts, and
// every dispatch under the predicate CONTROL_RUNNING. A solve still unconverged after a multiple of W
// updates (and inside its budget) clears CONTROL_RUNNING: the rest of the command buffer is skipped, the
// host sees it after the submission, records the next W iterations and the rest of that step, sets the
// predicate and goes on. The same updates run in the same order, so the results are the same bits as
// with the whole budget recorded (and as the mirror's, which records no window).
// With V_j = m / rho_0 and V grad_i W_ij = -(pressure_coef / rho_0) kernel_gradient r_hat_ij:
//   alpha_i = 1 / (|sum_j V grad W_ij|^2 + sum_j |V grad W_ij|^2)                     (dfsph_factor)
//   d_i = sum_j V (v_i - v_j) . grad W_ij, the density ratio's rate                   (dfsph_residual)
//   solve 1: r_i = max(d_i, 0), s_i = alpha_i r_i,           v_i -= sum_j V (s_i + s_j) grad W_ij
//   solve 2: r_i = max(rho_i / rho_0 + dt d_i* - 1, 0) (d* of v* = v + dt a),
//            s_i = alpha_i r_i / dt^2,                       a_i -= sum_j V (s_i + s_j) grad W_ij
//   (dfsph_velocity; kappa_i = sum over iterations of s_i, started at WARM_START times the last step's,
//   is the pressure p_i = kappa_i rho_i^2 / rho_0). Errors: solve 1
//   the mean of r_i dt, solve 2 the mean of r_i, against fluid.max_divergence_error and max_density_error.

const uint SOLVE_DIVERGENCE = 1u;       // D.level of the divergence-free solve's stages
const uint SOLVE_DENSITY = 2u;          // D.level of the constant-density solve's stages
const uint SOLVE_WARM_START = 3u;       // D.level of dfsph_velocity's warm start of the constant-density solve:
                                        // the acceleration of WARM_START times the last step's stiffness sum
                                        // (particle_kappa) of the particles a first residual finds compressed
                                        // (as SPlisHSPlasH's: an expanding region gets none), before the solve
const float WARM_START = 0.5;           // as SPlisHSPlasH: half the last pressure (a full one overshoots where
                                        // the flow decompresses, and the solve only ever adds pressure)

// control (uint): set by the host (max iterations), the stages and the check (dfsph_check.glsl)
const uint CONTROL_DONE = 0u;           // [CONTROL_DONE + solve]: 1 once the solve has stopped this step
const uint CONTROL_ITERATIONS = 2u;     // [CONTROL_ITERATIONS + solve]: its velocity updates this step
const uint CONTROL_STEP = 5u;           // steps completed (the device's count: the history's row)
const uint CONTROL_FAILURES = 6u;       // solves that spent their budget unconverged, since the start
const uint CONTROL_FAILED_STEP = 7u;    // the first of them: its step (1 = the first step)
const uint CONTROL_FAILED_SOLVE = 8u;   //   and its solve
const uint CONTROL_MAX_ITERATIONS = 9u; // fluid.max_iterations (host)
const uint CONTROL_OVERFLOW_STEP = 10u; // the first step (1 = the first) at which a particle had more than
                                        // MAX_NEIGHBOURS neighbours and images within h; 0: none
const uint CONTROL_FINISHED = 11u;      // dfsph_residual's work groups finished so far in this dispatch (the
                                        // last one runs the check and resets it to 0)
const uint CONTROL_RUNNING = 12u;       // 1: the recorded dispatches run; 0 once a solve spent its window (the
                                        // Vulkan host's predicate of conditional rendering: the rest is skipped)
const uint CONTROL_WINDOW = 13u;        // [CONTROL_WINDOW + solve]: the iterations the host recorded per window
                                        // of the solve (0: the whole budget, no window)
const uint CONTROL_DISPATCH = 16u;      // [dispatch_base(solve)]: the solve's indirect dispatch arguments,
                                        //   (x, y, z) work groups of its dfsph_velocity and dfsph_residual
const uint CONTROL_REBUILD = 22u;       // the state equation's reused lists (LIST_SKIN; no DFSPH, so its words are
                                        // free): 1 where the next step builds the lists (and sorts), 0 where it
                                        // walks the last ones; set by integrate, cleared by compute_forces
const uint CONTROL_BUILDS = 23u;        // the builds so far (compute_density)
const uint CONTROL_SIZE = 32u;

const uint IMAGE_SHIFT = 29u;           // neighbours: j | image << IMAGE_SHIFT (n < 2^29)
const uint NEIGHBOUR_MASK = (1u << IMAGE_SHIFT) - 1u;

uint dispatch_base(uint solve) { return CONTROL_DISPATCH + 8u * (solve - 1u); }

// The word of slot `slot` of particle i's list (and its entry of neighbour_gradients): slot-major on Vulkan, so
// that a work group's invocations touch consecutive words; particle-major with LIST_BY_PARTICLE (numba,
// Scene.spec_for), so that one thread walks one particle's slots in order (the other layout on the other
// backend was measured slower on both: H200 1 M particles 0.81 -> 1.31 ms a WCSPH step; numba 64,000
// 13.8 -> 13.3 ms, DFSPH 9,600 particles 10.1 -> 9.2 ms). With LIST_CHUNKS (Vulkan's state equation) the
// slot-major list is kept in chunks of 4 slots (chunk_index: chunk c of particle i is the 16 bytes at c n + i,
// which the shaders also declare as neighbour_chunks, uvec4): the scan stores 4 entries at once, where the GPU
// paid for each scattered word, and a walk loads them at once (neighbour_list.glsl: listed_word). Measured
// on the H200 at 1 M particles: the state equation's step 0.81 -> 0.74 ms (compute_density 0.39 -> 0.34 ms),
// DFSPH's 2.64 -> 2.70 ms in its stages (its sweeps read the lists ten times a step and were slower by
// chunks), so DFSPH keeps the words. A list holds its slots rounded up to a whole chunk
// (sphcore.sph.dfsph.list_width).
uint chunk_index(uint i, uint slot) { return (slot >> 2u) * P.n + i; }

// chunk[lane], by selects: read through a variable index, the walks' chunk was kept in memory instead of registers
// (the H200's compute_forces took 0.27 instead of 0.21 ms at 1 M particles). compute_density's scan writes
// chunk[lane] as it is: by selects that scan took 0.43 instead of 0.40 ms.
uint lane_of(uvec4 chunk, uint lane) { return lane == 0u ? chunk.x : lane == 1u ? chunk.y : lane == 2u ? chunk.z : chunk.w; }
uint list_slot(uint i, uint slot) {
    if (LIST_BY_PARTICLE) return i * MAX_NEIGHBOURS + slot;
    return LIST_CHUNKS ? chunk_index(i, slot) * 4u + (slot & 3u) : slot * P.n + i;
}

// dfsph_state (float): tolerances (host) and errors
const uint STATE_TOLERANCE = 0u;        // [STATE_TOLERANCE + solve]: fluid.max_divergence_error, max_density_error
const uint STATE_ERROR = 2u;            // [STATE_ERROR + solve]: the error the solve stopped at this step
const uint STATE_FAILED_ERROR = 5u;     // the error the first unconverged solve stopped at
const uint STATE_RELAXATION = 6u;       // fluid.relaxation (host): the share omega of each Jacobi update applied
const uint STATE_SIZE = 8u;

// dfsph_history (float, HISTORY_COLUMNS a row): one row per step, row (step - 1) % HISTORY_ROWS, written
// when the constant-density solve stops; the host reads it at least every HISTORY_ROWS steps
const uint HISTORY_ROWS = 256u;
const uint HISTORY_COLUMNS = 8u;        // step, dt, time, divergence iterations, divergence error,
                                        // density iterations, density error, 1 where both converged
const uint MIN_ITERATIONS_DIVERGENCE = 1u;  // as SPlisHSPlasH: at least one divergence update, and
const uint MIN_ITERATIONS_DENSITY = 2u;     // two density updates, per step
