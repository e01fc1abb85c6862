"""The public face of a run: `Simulation` (sphcore.stepper) steps a scene's particles on a backend;
`run` and `resume` (sphcore.runner) run it with snapshots, checkpoints and the final state; the health
checks of its state are in sphcore.health, its errors in sphcore.errors.
"""
from sphcore.checkpoint import CARRIED, CHECKPOINT
from sphcore.errors import CheckpointError, Interrupted, SimulationError
from sphcore.runner import final_arrays, load_checkpoint, note_resume, resume, run
from sphcore.scene import stable_dt
from sphcore.stepper import READ, Simulation

__all__ = ["CARRIED", "CHECKPOINT", "READ", "CheckpointError", "Interrupted", "Simulation", "SimulationError",
           "final_arrays", "load_checkpoint", "note_resume", "resume", "run", "stable_dt"]
