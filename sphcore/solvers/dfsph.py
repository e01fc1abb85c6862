"""DFSPH on the host (physics.pressure_solver = "dfsph"): its settings into the state, its per-step
log out of the device, and the report of a solve that did not converge (the solver's side of the
stepper: sphcore/solvers/state_equation.py).

The solve itself runs on the device with no readback (shaders/sph/dfsph.glsl describes how its loop
stops there). Each step's iteration counts and final errors land in a ring of
dfsph_history.HISTORY_ROWS rows; `SolverLog.collect` reads the ring after every chunk of at most that
many steps (Simulation.advance), so no row is overwritten before it is read.
"""
import warnings

import numpy as np

from sphcore.errors import ConvergenceWarning, SimulationError
from sphcore.solvers.state_equation import StateEquation
from sphcore.sph.dfsph import (CONTROL_FAILED_SOLVE, CONTROL_FAILED_STEP, CONTROL_FAILURES, CONTROL_MAX_ITERATIONS,
                               CONTROL_OVERFLOW_STEP, CONTROL_RUNNING, HISTORY_ROWS, SOLVE_DENSITY, SOLVE_DIVERGENCE,
                               SOLVE_WARM_START, STATE_FAILED_ERROR, STATE_RELAXATION, STATE_TOLERANCE)
from sphcore.stage import Stage

LOG_COLUMNS = ("step", "dt", "time", "divergence_iterations", "divergence_error", "density_iterations",
               "density_error", "converged")
SOLVES = {SOLVE_DIVERGENCE: ("divergence-free", "fluid.max_divergence_error"),
          SOLVE_DENSITY: ("constant-density", "fluid.max_density_error")}


def init_state(state, scene):
    """Write the scene's solver settings into `state` (of backends.empty_state, its positions set): the
    iteration budget into control, the two tolerances and the relaxation into dfsph_state; and the stiffness sum
    kappa = p / rho_0 of the hydrostatic pressure (Scene.hydrostatic_pressure) into particle_kappa, so
    that the first step's warm start holds part of the column up, as every later step's does (from
    zero, a Jacobi solve needs about as many iterations as the column is particles tall)."""
    x = state["particle_x"][:, :scene.dim]
    state["particle_kappa"][:] = scene.hydrostatic_pressure(x) / scene["fluid.rest_density"]
    state["control"][CONTROL_MAX_ITERATIONS] = scene["fluid.max_iterations"]
    state["control"][CONTROL_RUNNING] = 1  # (the predicate of the Vulkan host's windows: dfsph.glsl)
    state["dfsph_state"][STATE_TOLERANCE + SOLVE_DIVERGENCE] = scene["fluid.max_divergence_error"]
    state["dfsph_state"][STATE_TOLERANCE + SOLVE_DENSITY] = scene["fluid.max_density_error"]
    state["dfsph_state"][STATE_RELAXATION] = scene["fluid.relaxation"]


class DFSPH(StateEquation):
    """DFSPH's side of the stepper: its settings, its log (`log`, a SolverLog), read every HISTORY_ROWS steps
    at most, in checkpoints and final.npz, and a diverged solve as a blow-up's cause."""

    carried = ("dfsph_state", "particle_kappa")  # its tolerances and errors, and its warm start (control is generic)
    collect_every = HISTORY_ROWS

    def __init__(self, scene):
        super().__init__(scene)
        self.log = SolverLog(scene)  # each step's iterations and errors (final.npz: solver_log)

    def stages_before_forces(self):
        """The factor, then the divergence-free solve (dfsph.glsl)."""
        return [Stage("dfsph_factor")] + dfsph_solve(SOLVE_DIVERGENCE, self.scene["fluid.max_iterations"])

    def stages_after_dt(self):
        """The constant-density solve once the step's dt is known: v* = v + dt a, the warm start where the first
        residual finds compression, as SPlisHSPlasH's; then the solve."""
        return [Stage("dfsph_predict"), Stage("dfsph_residual", SOLVE_DENSITY), Stage("dfsph_velocity", SOLVE_WARM_START)
                ] + dfsph_solve(SOLVE_DENSITY, self.scene["fluid.max_iterations"])

    def init_state(self, state):
        init_state(state, self.scene)

    def collect(self, backend, first, last):
        self.log.collect(backend, first, last)

    def restore(self, arrays, step):
        if "solver_log" in arrays:  # (a replay's restore keeps the rows it has)
            self.log.rows = {int(r[0]): np.array(r, np.float64) for r in arrays["solver_log"] if 0 < r[0] <= step}
            self.log.reported = int(arrays["buffer_control"][CONTROL_FAILURES])  # reported then

    def blow_up_cause(self):
        return self.log.diverged()

    def checkpoint_arrays(self):
        return {"solver_log": self.log.array()}  # each step's iterations and errors so far: a resumed run's is whole

    def final_arrays(self):
        return {"solver_log": self.log.array(), "solver_log_columns": np.array(LOG_COLUMNS)}


def dfsph_solve(solve, iterations):
    """One DFSPH solve as recorded: the residual (whose last work group runs the convergence check), then
    `iterations` times an update and the residual, dispatched indirectly. Once a check stops the solve, it
    zeroes their group counts: the loop ends on the device, with no readback, and both backends run the
    same updates."""
    return [Stage("dfsph_residual", solve)] + [Stage(name, solve, True) for name in ("dfsph_velocity",
                                                                                  "dfsph_residual")] * iterations


class SolverLog:
    """The rows of dfsph_history, one per step (LOG_COLUMNS), keyed by step; unconverged solves are
    reported as ConvergenceWarnings naming the step, the solve, the error reached and the tolerance."""

    def __init__(self, scene):
        self.scene, self.rows, self.reported = scene, {}, 0

    def collect(self, backend, first, last):
        """Read the rows of steps first + 1 .. last (at most HISTORY_ROWS of them) and report what did
        not converge; raise SimulationError if a particle's neighbour list overflowed (two readbacks)."""
        if last - first > HISTORY_ROWS:
            raise ValueError(f"steps {first + 1}..{last}: the history ring holds {HISTORY_ROWS} steps")
        if last <= first:
            return
        history = backend.read_buffer("dfsph_history")
        for step in range(first + 1, last + 1):
            row = history[(step - 1) % HISTORY_ROWS].astype(np.float64)
            if int(row[0]) != step:  # the step count is the device's and the host's: they cannot differ
                raise RuntimeError(f"DFSPH history: row for step {step} holds step {int(row[0])}")
            self.rows[step] = row
        control = backend.read_buffer("control")
        failures = int(control[CONTROL_FAILURES])
        if failures > self.reported:
            self.warn(control, backend.read_buffer("dfsph_state"), failures, last)
            self.reported = failures
        if control[CONTROL_OVERFLOW_STEP]:
            self.overflow(backend, int(control[CONTROL_OVERFLOW_STEP]), last)

    def overflow(self, backend, step, last):
        """Raise SimulationError for a neighbour list overflow first seen at `step` (the steps up to `last`
        ran): name the slots, and the particle with the longest list now."""
        count = backend.read_buffer("neighbour_count")
        k = int(np.argmax(count))
        particle = int(backend.read_buffer("particle_id")[k])
        diverged = self.diverged()
        raise SimulationError(
            f"step {step}: a particle had more neighbours and wall images within h than its neighbour list's "
            f"{self.scene.max_neighbours} slots (fluid.max_neighbours); at step {last} particle {particle} has "
            f"{int(count[k])}. The solves would lose pairs, so the run stops here: "
            + (f"likely cause: {diverged}" if diverged else
               "raise fluid.max_neighbours, or look for particles crowding together (a blow-up)"))

    def warn(self, control, state, failures, last):
        scene = self.scene
        bad = [r for s, r in sorted(self.rows.items()) if r[7] == 0 and s > 0]
        solve = int(control[CONTROL_FAILED_SOLVE])
        name, key = SOLVES.get(solve, ("?", "?"))
        first = (f"the first at step {int(control[CONTROL_FAILED_STEP])}: the {name} solve stopped at error "
                 f"{float(state[STATE_FAILED_ERROR]):.3g} > {key} = {scene[key]:g}")
        latest = ""
        if bad:
            r = bad[-1]
            latest = (f"; the latest at step {int(r[0])} (t = {r[2]:.4g} s): divergence error {r[4]:.3g} after "
                      f"{int(r[3])} updates, density error {r[6]:.3g} after {int(r[5])}")
        advice = self.diverged() or "raise fluid.max_iterations, lower time.cfl_number, or loosen the tolerance"
        warnings.warn(ConvergenceWarning(
            f"DFSPH did not converge within fluid.max_iterations = {scene['fluid.max_iterations']} in {failures} "
            f"solve(s) up to step {last}; {first}{latest}. {advice[0].upper()}{advice[1:]}"), stacklevel=3)

    def diverged(self):
        """Where the latest unconverged step's solve ran away (its error above 1, a compression of 100 %, or
        not finite: a Jacobi iteration that diverges), what to do; else None."""
        unconverged = [r for s, r in sorted(self.rows.items()) if r[7] == 0 and s > 0]
        if not unconverged:
            return None
        r = unconverged[-1]
        for name, error, updates in (("divergence-free", r[4], r[3]), ("constant-density", r[6], r[5])):
            if not np.isfinite(error) or error > 1.0:
                return (f"the {name} solve diverged at step {int(r[0])} (error {error:.3g} after {int(updates)} "
                        f"updates): lower fluid.relaxation (now {self.scene['fluid.relaxation']:g}; a support of 4 dx "
                        "needs about 0.5)")
        return None

    def array(self):
        """The rows in step order, (steps, len(LOG_COLUMNS)) float64."""
        return np.array([self.rows[s] for s in sorted(self.rows)], np.float64).reshape(-1, len(LOG_COLUMNS))
