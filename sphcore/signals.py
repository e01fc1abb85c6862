"""SIGINT and SIGTERM during a run: the handler only records the signal, the run acts on it.

A Python signal handler runs between two bytecodes of the main thread, wherever that is: inside
numba's compiler, or in a ctypes callback of llvmlite, where an exception raised by the handler
is dropped (the run went on and exited 0) or leaves the compiler in a broken state (a segfault).
So the handler here only notes the signal, and the run checks at its safe points: between the
start-up's stages (each kernel compiled, each first launch) with `poll()`, and between chunks of
steps, where it writes a checkpoint first. Once the run steps (`stepping` set), a second signal
stops it at once: the steps run in compiled code or in the Vulkan driver, not in a callback, and
every file is written under a temporary name and renamed, so none is left half written.
"""
import signal
import threading

from sphcore.errors import Interrupted


class Signals:
    """Records SIGINT and SIGTERM for the length of a `with` block (main thread only; a signal set
    to be ignored stays ignored). `received`: the first signal, or None."""

    def __init__(self):
        self.received, self.stepping, self._previous = None, False, {}

    def __enter__(self):
        if threading.current_thread() is threading.main_thread():
            for signum in (signal.SIGINT, signal.SIGTERM):
                if signal.getsignal(signum) is not signal.SIG_IGN:
                    self._previous[signum] = signal.signal(signum, self._handle)
        return self

    def __exit__(self, *exc):
        for signum, handler in self._previous.items():
            signal.signal(signum, handler)

    def _handle(self, signum, frame):
        if self.received is None:
            self.received = signum
        elif self.stepping:
            raise Interrupted(signum)

    def poll(self, message="during start-up, before the first step; nothing was written that a later run needs"):
        """A safe point: raise Interrupted if a signal was received."""
        if self.received is not None:
            raise Interrupted(self.received, f"interrupted by {signal.Signals(self.received).name} {message}")


class HeldInterrupt:
    """Holds Ctrl-C (SIGINT) for the length of a `with` block, where Python's default handler is in
    place and the block runs in the main thread: the signal only sets `received`, and the block stops
    at its next safe point and raises KeyboardInterrupt itself (Simulation.advance: after the chunk of
    steps it arrived in, counted). Elsewhere (sphcore.run's Signals, a handler of the caller's,
    another thread) nothing changes and `received` stays None."""

    def __init__(self):
        self.received, self._previous = None, None

    def __enter__(self):
        if (threading.current_thread() is threading.main_thread()
                and signal.getsignal(signal.SIGINT) is signal.default_int_handler):
            self._previous = signal.signal(signal.SIGINT, self._handle)
        return self

    def __exit__(self, *exc):
        if self._previous is not None:
            signal.signal(signal.SIGINT, self._previous)
            self._previous = None

    def _handle(self, signum, frame):
        self.received = signum
