"""The state equation (physics.pressure_solver = "state_equation"): the pressure follows from the density
(shaders/sph/equation_of_state.glsl), so the stepper needs nothing more than its generic step.

This class is also the interface every solver gives the stepper (sphcore.simulation.Simulation), each
method here the do-nothing of a solver with no state or log of its own; a solver overrides what it
needs (sphcore/solvers/dfsph.py). A new solver is a module here and a line in SOLVERS (__init__.py).
"""
import math


class StateEquation:
    """What the stepper asks of a pressure solver; the state equation's answers."""

    carried = ()  # buffers beyond the generic ones that carry the solver's state from step to step
    collect_every = math.inf  # the most steps between two reads of the solver's log (collect)

    def __init__(self, scene):
        self.scene = scene

    def stages_before_forces(self):
        """The solver's stages of a step between the density and the forces (sphcore.plan.plan)."""
        return []

    def stages_after_dt(self):
        """Its stages once the step's dt is known, before the particles move."""
        return []

    def init_state(self, state):
        """Write the solver's settings into `state` (backends.empty_state, its positions set)."""

    def collect(self, backend, first, last):
        """Read what the device logged over steps first + 1 .. last (at most collect_every of them)."""

    def restore(self, arrays, step):
        """Take back from a checkpoint's `arrays` what the solver logged up to `step`."""

    def blow_up_cause(self):
        """The likely cause of a blow-up the solver itself can name, else None."""
        return None

    def checkpoint_arrays(self):
        """What a checkpoint holds of the solver beyond the carried buffers."""
        return {}

    def final_arrays(self):
        """What final.npz holds of the solver."""
        return {}
