"""Ctrl-C during a run, taken between two steps.

Python raises KeyboardInterrupt wherever the main thread happens to be when SIGINT
arrives: inside the trace's MCAP writer halfway through a chunk, inside a key's capture,
between a step's state update and its report. The run would then save a trace that does
not read back. While a run holds a ``StepBoundary``, SIGINT only sets ``requested``; the
runner calls ``check`` before each step (and each batch), which raises KeyboardInterrupt
there, where everything written so far is whole. A second Ctrl-C before the run reaches a
boundary raises at once (a way out of anything that does not come back to the loop).

Only the main thread can set a signal handler, and only the default one is replaced:
a run in a worker thread, or in a process that ignores SIGINT, keeps what it has."""

from __future__ import annotations

import signal
import threading


class StepBoundary:
    """A context in which SIGINT waits for the run's next ``check``."""

    def __init__(self) -> None:
        self.requested = False
        self._previous = None

    def __enter__(self) -> StepBoundary:
        main = threading.current_thread() is threading.main_thread()
        if main and signal.getsignal(signal.SIGINT) is signal.default_int_handler:
            self._previous = signal.signal(signal.SIGINT, self._on_sigint)
        return self

    def __exit__(self, *exc) -> None:
        if self._previous is not None:
            signal.signal(signal.SIGINT, self._previous)
            self._previous = None

    def _on_sigint(self, signum, frame) -> None:
        if self.requested:
            raise KeyboardInterrupt
        self.requested = True

    def check(self) -> None:
        """Raise KeyboardInterrupt if Ctrl-C was pressed since the run began."""
        if self.requested:
            raise KeyboardInterrupt
