"""Run one command line in this process and list what a user must never see from it: a
traceback, a hang, a stray warning, an error of more than one line or with unprintable text,
an exit status outside the README's table."""

from __future__ import annotations

import contextlib
import os
import signal
import time
import warnings
from dataclasses import dataclass, field

from click.testing import CliRunner

from puppetcli.cli import cli

MAX_ERROR_LINE = 460  # characters of an ``error:`` line: a message of at most 400 (one_line), the
# prefix and the pointer to --help of a usage error


class Hang(Exception):
    """Raised by the alarm when a command runs past its bound."""


@dataclass
class Outcome:
    args: list[str]
    code: int | None
    stdout: str
    stderr: str
    exception: BaseException | None
    warnings: list[str] = field(default_factory=list)
    seconds: float = 0.0

    def keeps_outputs(self) -> bool:
        """Whether the run must have left existing outputs as they were: it failed, and not
        in the simulation or its expectations (those save what was captured, as documented)."""
        if self.code == 0:
            return False
        saved = ("simulation failed at", "expectations failed", "expectation failed")
        return not any(word in self.stderr for word in saved)

    def problems(self) -> list[str]:
        """What is wrong with this outcome for a user (empty: it is fine)."""
        out = []
        if isinstance(self.exception, Hang):
            out.append(f"hang: still running after {self.seconds:.0f} s")
        elif self.exception is not None and not isinstance(self.exception, SystemExit):
            out.append(f"traceback: {type(self.exception).__name__}: {self.exception!s:.300}")
        if self.code not in (0, 1, 2):
            out.append(f"exit status {self.code}")
        out += [f"warning leaked: {w:.300}" for w in self.warnings]
        if "Traceback" in self.stderr:
            out.append("a traceback on stderr")
        errors = [line for line in self.stderr.splitlines() if line.startswith("error:")]
        if len(errors) > 1:
            out.append(f"{len(errors)} error lines")
        if self.code == 1 and not errors:
            out.append(f"exit 1 without an error line: {self.stderr[-300:]!r}")
        for line in errors:
            if len(line) > MAX_ERROR_LINE:
                out.append(f"error line of {len(line)} characters: {line[:200]!r}")
            if not line.isprintable():
                out.append(f"unprintable error line: {line[:200]!r}")
        return out


@contextlib.contextmanager
def _alarm(seconds: float):
    def ring(signum, frame):
        raise Hang()

    old = signal.signal(signal.SIGALRM, ring)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


def run_cli(args: list[str], bound: float = 30.0) -> Outcome:
    """Run ``puppetcli ARGS`` in this process, stopped with :class:`Hang` after ``bound`` s."""
    runner = CliRunner()
    start = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught, _alarm(bound):
        warnings.simplefilter(os.environ.get("FUZZ_WARNINGS", "always"))
        result = runner.invoke(cli, args, catch_exceptions=True)
    return Outcome(
        args=args,
        code=result.exit_code,
        stdout=result.stdout,
        stderr=result.stderr,
        exception=result.exception,
        warnings=[f"{w.category.__name__}: {w.message} ({w.filename}:{w.lineno})" for w in caught],
        seconds=time.perf_counter() - start,
    )
