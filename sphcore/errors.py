"""Every error and warning sphcore raises, in one module that imports nothing of sphcore.

Each is also importable where it was first defined (sphcore.scene.SceneError,
sphcore.simulation.SimulationError, sphcore.vk_runner.VulkanError, ...). A message is one line that
says what went wrong and where (the file, the key, the step, the particle) and what to do.
"""
import signal


class SceneError(ValueError):
    """A scene that cannot be run; the message names the file and the key.

    >>> import sphcore
    >>> sphcore.Scene.from_dict({"fluid": {"spacing": -1.0}})
    Traceback (most recent call last):
    sphcore.errors.SceneError: fluid.spacing = -1.0: must be within [1e-05, 1] m
    """


class FolderError(SceneError):
    """An output folder that a run cannot use as it is; the message names the folder and what to do."""


class MemoryLimitError(SceneError):
    """A run that would not fit in the memory available; the message gives both figures and what would fit."""


class RefusedByRanks(SceneError):
    """A run every rank of sphcore.parallel refuses before it starts (parallel.check, on each): rank 0 says why, once,
    and every rank exits."""


class ResultsError(SceneError):
    """A results file that cannot be used; the message names it and says what is wrong with it (`why`)."""


class SimulationError(RuntimeError):
    """The state became non-finite or left the box; the message names step, particle and likely cause.
    Also what a closed Simulation raises when it is used:

    >>> import sphcore
    >>> with sphcore.Simulation(sphcore.Scene.from_dict({"fluid": {"spacing": 0.05}})) as sim:
    ...     sim.step(10)
    >>> sim.read()
    Traceback (most recent call last):
    sphcore.errors.SimulationError: Simulation.read(): this Simulation of 'scene' is closed ...
    """


class CheckpointError(SimulationError):
    """A run that cannot be resumed: no checkpoint, an unreadable one, or one that does not belong
    to the scene (or to this version's parameter block); the message names the file."""


class SweepError(SimulationError):
    """A sweep that cannot start (no scheduler at the address, a bad option)."""


class CheckpointFieldError(ValueError):
    """A member of a checkpoint that does not fit the scene: `field` names it."""

    def __init__(self, field, message):
        self.field = field
        super().__init__(f"field {field}: {message}")


class VulkanError(RuntimeError):
    """A Vulkan failure, with what to do about it in the message."""


class ShaderCompileError(RuntimeError):
    """No compiler, or the compiler rejected a shader (its message names file and line)."""


class Interrupted(KeyboardInterrupt):
    """SIGINT or SIGTERM stopped a run; `signum` is the signal (a shell's exit status is 128 + it)."""

    def __init__(self, signum, message=None):
        self.signum = signum
        super().__init__(message or f"interrupted by {signal.Signals(signum).name}; files written so far are complete")


class BadEntry(Exception):
    """A cache entry that must not be used (sphcore.cache_trust); its message says why."""


class CacheWarning(UserWarning):
    """A cache folder or entry was not used (untrusted, damaged or unwritable); the code was compiled."""


class ConvergenceWarning(UserWarning):
    """A DFSPH solve spent fluid.max_iterations updates without reaching its tolerance."""
