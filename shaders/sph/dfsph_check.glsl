// DFSPH's convergence test of solve D.level (dfsph.glsl), run by the last of dfsph_residual's work groups
// to finish: the mean residual, summed in a fixed order (the work groups' sums, dfsph_partial; each
// invocation its strided share of them in index order, then invocation 0 the shares in order: no atomics
// in the sum, the same bits on every run whichever group finishes last, and up to the arithmetic's
// rounding on both backends), is the solve's error (divergence-free: times dt). Once it is under the
// solve's tolerance after its minimum iterations, or fluid.max_iterations updates are spent, the solve's
// done flag is set and its indirect dispatches' work groups are zeroed: the rest of its recorded iterations
// dispatch nothing. One going on at the end of the host's window of recorded iterations clears the
// predicate CONTROL_RUNNING (dfsph.glsl: windows). A solve stopped unconverged is counted and the first
// one recorded (step, solve, error). The constant-density solve's stop ends the step: a row of dfsph_history.
// Needs time_state, control, dfsph_state, dfsph_history, dfsph_partial and the shared s_sum declared
// by the shader that includes this file (after dfsph.glsl).
// Mirror: sphcore/sph/dfsph_check.py (same names, same statements).

// Invocation lid's share: the sums of groups lid, lid + L, lid + 2 L, ... of `groups`, in index order.
real dfsph_check_share(uint lid, uint groups) {
    real sum = real(0.0);
    for (uint k = lid; k < groups; k += gl_WorkGroupSize.x) sum += dfsph_partial[k];
    return sum;
}

// Invocation 0, once every share is in s_sum: the error, and the solve's stop.
void dfsph_check_decide(uint solve) {
    // the shares in order, their mean: the error (divergence-free: times dt, the last step's, or P.dt
    // before the first)
    real total = real(0.0);
    for (uint k = 0u; k < gl_WorkGroupSize.x; ++k) total += s_sum[k];
    float error = float(total / real(P.n));
    if (solve == SOLVE_DIVERGENCE) error *= time_state[0].x > 0.0 ? time_state[0].x : P.dt;
    // stop: converged after the minimum iterations, or the budget spent
    uint iterations = control[CONTROL_ITERATIONS + solve];
    uint least = solve == SOLVE_DENSITY ? MIN_ITERATIONS_DENSITY : MIN_ITERATIONS_DIVERGENCE;
    bool converged = iterations >= least && error <= dfsph_state[STATE_TOLERANCE + solve];
    if (!converged && iterations < control[CONTROL_MAX_ITERATIONS]) {
        // going on; at the end of a recorded window, the rest of the command buffer is skipped (dfsph.glsl)
        uint window = control[CONTROL_WINDOW + solve];
        if (window > 0u && iterations > 0u && iterations % window == 0u) control[CONTROL_RUNNING] = 0u;
        return;
    }
    control[CONTROL_DONE + solve] = 1u;
    control[dispatch_base(solve)] = 0u;
    dfsph_state[STATE_ERROR + solve] = error;
    // a solve that spent its budget unconverged: counted, the first one recorded
    if (!converged) {
        control[CONTROL_FAILURES] += 1u;
        if (control[CONTROL_FAILURES] == 1u) {
            control[CONTROL_FAILED_STEP] = control[CONTROL_STEP] + 1u;
            control[CONTROL_FAILED_SOLVE] = solve;
            dfsph_state[STATE_FAILED_ERROR] = error;
        }
    }
    // the constant-density solve ends the step: its history row, the step count
    if (solve != SOLVE_DENSITY) return;
    uint step = control[CONTROL_STEP] + 1u;
    uint row = (step - 1u) % HISTORY_ROWS * HISTORY_COLUMNS;
    float divergence_error = dfsph_state[STATE_ERROR + SOLVE_DIVERGENCE];
    bool both = converged && divergence_error <= dfsph_state[STATE_TOLERANCE + SOLVE_DIVERGENCE];
    dfsph_history[row] = float(step);
    dfsph_history[row + 1u] = time_state[0].x;
    dfsph_history[row + 2u] = time_state[0].z + time_state[0].w;
    dfsph_history[row + 3u] = float(control[CONTROL_ITERATIONS + SOLVE_DIVERGENCE]);
    dfsph_history[row + 4u] = divergence_error;
    dfsph_history[row + 5u] = float(iterations);
    dfsph_history[row + 6u] = error;
    dfsph_history[row + 7u] = both ? 1.0 : 0.0;
    control[CONTROL_STEP] = step;
}
