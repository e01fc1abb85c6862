"""The pressure solvers, one module each, chosen by physics.pressure_solver (sphcore.solvers.state_equation
describes what a solver gives the stepper)."""
from sphcore.solvers.dfsph import DFSPH
from sphcore.solvers.state_equation import StateEquation

SOLVERS = {"state_equation": StateEquation, "dfsph": DFSPH}  # physics.pressure_solver -> its class


def solver_for(scene):
    """The solver of `scene` (physics.pressure_solver)."""
    return SOLVERS[scene["physics.pressure_solver"]](scene)
