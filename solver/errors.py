"""The one exception family of puppetcli.

Library code raises subclasses of ``PuppetError``; the CLI turns them into a
one-line ``error: …`` and a non-zero exit.  The solver only raises
``SimulationError``; the file-facing subclasses live in ``puppetcli.errors``.
"""

from __future__ import annotations


class PuppetError(Exception):
    """A user-facing problem: the message is one line and names what went wrong."""


class SimulationError(PuppetError):
    """Numerical trouble detected during a step.

    step: index of the step that failed; time: its start time (s);
    bone: the bone (or joint) involved, if one can be named.
    """

    def __init__(self, message: str, step: int, time: float, bone: str | None) -> None:
        where = f"step {step} (t = {time:.6g} s)"
        if bone is not None:
            where += f", bone '{bone}'"
        super().__init__(f"simulation failed at {where}: {message}")
        self.step = step
        self.time = time
        self.bone = bone
