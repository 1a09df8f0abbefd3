"""User-facing errors of the file-facing layer (rigs, scripts, sessions), and how values and
messages are shown in them: every error is one printable line, whatever a file held."""

from __future__ import annotations

import reprlib

from solver.errors import PuppetError, SimulationError

__all__ = [
    "Interrupted", "OverBudget", "PuppetError", "RigError", "RunStopped", "ScriptError",
    "SessionError", "SimulationError", "clip", "one_line", "shown",
]  # fmt: skip

MAX_LINE = 400  # characters of an error line; a message longer than this is cut in the middle

_SHORT = reprlib.Repr()  # (keyword arguments only from Python 3.12)
_SHORT.maxlevel, _SHORT.maxstring, _SHORT.maxlong, _SHORT.maxother = 2, 40, 24, 40
_SHORT.maxlist = _SHORT.maxtuple = _SHORT.maxset = _SHORT.maxarray = _SHORT.maxdict = 4


class RigError(PuppetError):
    """A rig file is unreadable or invalid."""


class ScriptError(PuppetError):
    """A manipulation script is unreadable or invalid."""


class SessionError(PuppetError):
    """A recorded session file is unreadable or invalid."""


class RunStopped(PuppetError):
    """A run stopped before its end; what it captured is saved, as for a broken simulation."""


class OverBudget(RunStopped):
    """A run whose measured pace shows it would take far longer than its budget."""


class Interrupted(RunStopped):
    """The user pressed Ctrl-C (SIGINT) during a run: what it captured is saved; status 130."""

    exit_code = 130

    def __init__(self, step: int, time: float) -> None:
        super().__init__(f"interrupted at step {step} (t = {time:.6g} s)")
        self.step, self.time = step, time


def shown(value: object) -> str:
    """``value`` for the ``got …`` of an error: its repr, escaped, at most about 40 characters
    (long strings, numbers and lists cut with ``...``, nesting beyond two levels elided)."""
    return _SHORT.repr(value)


def clip(text: str, limit: int = 40) -> str:
    """``text`` from a file, as written but escaped to one printable line and cut to
    ``limit`` characters with ``…``."""
    text = _escaped(text[: limit * 4])
    return text if len(text) <= limit else text[: limit - 1] + "…"


def one_line(message: str) -> str:
    """``message`` as one printable line of at most MAX_LINE characters: line breaks and
    control characters escaped, a too long middle replaced by ``…``."""
    text = _escaped(message)
    if len(text) <= MAX_LINE:
        return text
    half = (MAX_LINE - 1) // 2
    return f"{text[:half]}…{text[-half:]}"


def _escaped(text: str) -> str:
    return "".join(c if c.isprintable() else c.encode("unicode_escape").decode() for c in text)
