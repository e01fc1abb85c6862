"""DFSPH's convergence test of solve D.level (dfsph.py), run by the last of dfsph_residual's work groups
to finish: the mean residual in a fixed order (of the work groups' sums) is the solve's error; under the
tolerance after the minimum iterations, or with the budget spent, the solve's done flag is set and its
indirect dispatches' work groups zeroed (going on at the end of a window of recorded iterations, the
predicate CONTROL_RUNNING cleared); an unconverged stop is counted and the first recorded; the
constant-density solve's stop writes the step's row of dfsph_history.

Mirror of shaders/sph/dfsph_check.glsl: same names, same statements. dfsph_residual's launch calls
dfsph_check_share for each invocation, then dfsph_check_decide, once every work group has run (the
shader's last group to finish). Its float32 arithmetic is numpy's, in the shader's order.
"""
from functools import lru_cache

import numpy as np
from numba import njit

from sphcore.sph import named
from sphcore.sph.dfsph import (CONTROL_DONE, CONTROL_FAILED_SOLVE, CONTROL_FAILED_STEP, CONTROL_FAILURES,
                               CONTROL_ITERATIONS, CONTROL_MAX_ITERATIONS, CONTROL_RUNNING, CONTROL_STEP,
                               CONTROL_WINDOW, HISTORY_ROWS, MIN_ITERATIONS_DENSITY, MIN_ITERATIONS_DIVERGENCE,
                               SOLVE_DENSITY, SOLVE_DIVERGENCE, STATE_ERROR, STATE_FAILED_ERROR, STATE_TOLERANCE,
                               dispatch_base)

f32 = np.float32


@lru_cache(maxsize=None)
def dfsph_check(spec, real=np.float32):

    @njit
    def dfsph_check_share(lid, groups, local_size, dfsph_partial):
        """Invocation lid's share: the sums of groups lid, lid + L, lid + 2 L, ... of `groups`, in index order."""
        sum = real(0.0)
        for k in range(lid, groups, local_size):
            sum += dfsph_partial[k]
        return sum

    @njit
    def dfsph_check_decide(solve, local_size, params, time_state, control, dfsph_state, dfsph_history, s_sum):
        """Invocation 0, once every share is in s_sum: the error, and the solve's stop."""
        P = params[0]
        # the shares in order, their mean: the error (divergence-free: times dt, the last step's, or P.dt
        # before the first)
        total = real(0.0)
        for k in range(local_size):
            total += s_sum[k]
        error = f32(total / real(P.n))
        if solve == SOLVE_DIVERGENCE:
            error *= time_state[0, 0] if time_state[0, 0] > f32(0.0) else P.dt
        # stop: converged after the minimum iterations, or the budget spent
        iterations = control[CONTROL_ITERATIONS + solve]
        least = MIN_ITERATIONS_DENSITY if solve == SOLVE_DENSITY else MIN_ITERATIONS_DIVERGENCE
        converged = iterations >= least and error <= dfsph_state[STATE_TOLERANCE + solve]
        if not converged and iterations < control[CONTROL_MAX_ITERATIONS]:
            # going on; at the end of a recorded window, the rest of the command buffer is skipped (dfsph.py)
            window = control[CONTROL_WINDOW + solve]
            if window > 0 and iterations > 0 and iterations % window == 0:
                control[CONTROL_RUNNING] = 0
            return
        control[CONTROL_DONE + solve] = 1
        control[dispatch_base(solve)] = 0
        dfsph_state[STATE_ERROR + solve] = error
        # a solve that spent its budget unconverged: counted, the first one recorded
        if not converged:
            control[CONTROL_FAILURES] += 1
            if control[CONTROL_FAILURES] == 1:
                control[CONTROL_FAILED_STEP] = control[CONTROL_STEP] + 1
                control[CONTROL_FAILED_SOLVE] = solve
                dfsph_state[STATE_FAILED_ERROR] = error
        # the constant-density solve ends the step: its history row, the step count
        if solve != SOLVE_DENSITY:
            return
        step = control[CONTROL_STEP] + 1
        row = (step - 1) % HISTORY_ROWS
        divergence_error = dfsph_state[STATE_ERROR + SOLVE_DIVERGENCE]
        both = converged and divergence_error <= dfsph_state[STATE_TOLERANCE + SOLVE_DIVERGENCE]
        dfsph_history[row, 0] = f32(step)
        dfsph_history[row, 1] = time_state[0, 0]
        dfsph_history[row, 2] = time_state[0, 2] + time_state[0, 3]
        dfsph_history[row, 3] = f32(control[CONTROL_ITERATIONS + SOLVE_DIVERGENCE])
        dfsph_history[row, 4] = divergence_error
        dfsph_history[row, 5] = f32(iterations)
        dfsph_history[row, 6] = error
        dfsph_history[row, 7] = f32(1.0) if both else f32(0.0)
        control[CONTROL_STEP] = step

    return named(dfsph_check_share, dfsph_check_decide)
