"""User-facing errors of the file-facing layer (rigs, scripts, sessions)."""

from __future__ import annotations

from solver.errors import PuppetError, SimulationError

__all__ = ["PuppetError", "RigError", "ScriptError", "SessionError", "SimulationError"]


class RigError(PuppetError):
    """A rig file is unreadable or invalid."""


class ScriptError(PuppetError):
    """A manipulation script is unreadable or invalid."""


class SessionError(PuppetError):
    """A recorded session file is unreadable or invalid."""
