"""The one-off cost of a first run: numba compiles the solver (a few minutes) and caches it.

``warm_up(prepare)`` runs ``prepare`` (a throwaway step that makes the compiled kernels
ready) before a command's timed work.  When it takes longer than ``NOTICE_AFTER`` seconds
(numba is compiling, not loading its cache) it says so once on stderr and, when done, how
long it took; so a first run does not look hung, and compiling is never counted as
simulation (steps/s, a progress bar's estimate).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

import click

__all__ = ["NOTICE_AFTER", "warm_up", "warm_up_step"]

NOTICE_AFTER = 2.0  # s: loading the cache takes ~0.5 s; longer means compiling
COMPILING = (
    "compiling the solver: the first run on this machine takes 2-3 minutes "
    "(later runs load it in under a second)"
)


def warm_up(prepare: Callable[[], object]) -> None:
    """Run ``prepare``; announce a compile that takes long (module docstring)."""
    notice = threading.Timer(NOTICE_AFTER, lambda: click.echo(COMPILING, err=True))
    notice.daemon = True
    notice.start()
    started = time.perf_counter()
    try:
        prepare()
    finally:
        notice.cancel()
    took = time.perf_counter() - started
    if took > NOTICE_AFTER:
        click.echo(f"solver ready ({took:.0f} s)", err=True)


def compile_engine(model) -> None:
    """One throwaway step of ``model`` from rest on each of its engine's paths, in place
    (a run's steps) and to a new State (a step the stepper hands back): numba compiles or
    loads them now rather than in the middle of a run."""
    from solver.engine import Engine
    from solver.state import initial_state

    engine = Engine(model)
    engine.stepper().advance()
    engine.step(initial_state(model))


def warm_up_step(model) -> None:
    """``warm_up`` of ``compile_engine(model)``."""
    warm_up(lambda: compile_engine(model))
