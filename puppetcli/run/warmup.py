"""The first run on a machine: numba compiles the solver (2-3 minutes) and caches it.

A command picks the engine its run steps with (``prepare_engine``; the ``--engine``
option of puppetcli.commands.options, or ``PUPPETCLI_ENGINE``):

- ``auto`` (the default): the compiled step when it is built; otherwise the build starts in
  a detached background process (``python -m puppetcli.run.warmup RIG``, one at a time) and this
  run starts on the numpy step (``solver.pipeline``), moving to the compiled step between two
  actions as soon as the build is done (``Runner.upgrade``).  The two give the same states to
  rounding: the example scripts' keys agree within 1e-9 (tests/puppetcli/run/test_warmup.py).
- ``compiled``: wait for the compiled step (saying once that it is compiling, and how long
  it took, when that takes more than ``NOTICE_AFTER`` s); compiling is never counted as
  simulation (steps/s, a progress bar's estimate).
- ``numpy``: the numpy step throughout.

A run on the compiled step leaves a warm daemon behind for the next commands
(puppetcli.daemon).

Whether the compiled step is built: puppetcli.run.build.
"""

from __future__ import annotations

import contextlib
import gc
import os
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

import click

from puppetcli.daemon.serve import start as start_daemon
from puppetcli.run.build import compile_engine, compiled_ready, marker

__all__ = [
    "ENGINES", "NOTICE_AFTER", "first_step", "freeze_loaded", "prepare_engine", "start_build",
    "warm_up", "warm_up_step",
]  # fmt: skip

ENGINES = ("auto", "compiled", "numpy")
NOTICE_AFTER = 2.0  # s: loading the cache takes ~0.3 s; longer means compiling
COMPILING = (
    "compiling the solver: the first run on this machine takes 2-3 minutes "
    "(later runs load it in under a second)"
)
FIRST_STEP = "the first step is taking a while (a large rig, or the solver loading from its cache)"
COMPILING_NUMPY = "compiling the kernels the numpy solver shares with the compiled one (seconds)"
NUMPY_READY = "numpy solver ready"
BUILDING = (
    "first run on this machine: the compiled solver is being built in the background "
    "(2-3 minutes); until it is ready this run steps with the numpy solver, which is slower "
    "and gives the same keys to 1e-9"
)


def warm_up(
    prepare: Callable[[], object], compiling: str = COMPILING, ready: str = "solver ready"
) -> None:
    """Run ``prepare``; announce a compile that takes long (module docstring) with the line
    ``compiling``, then ``ready`` and how long it took."""
    notice = threading.Timer(NOTICE_AFTER, lambda: click.echo(compiling, err=True))
    notice.daemon = True
    notice.start()
    started = time.perf_counter()
    try:
        prepare()
    finally:
        notice.cancel()
    took = time.perf_counter() - started
    if took > NOTICE_AFTER:
        click.echo(f"{ready} ({took:.0f} s)", err=True)


def first_step(model) -> None:
    """One throwaway in-place step of ``model`` on its engine: loads (or, for the numpy
    step's shared kernels, compiles) what a run's steps need now, not in the first timed
    step; the compiled step's rare paths (a step handed back) load when one happens."""
    from solver.engine import Engine

    Engine(model).stepper().advance()


def freeze_loaded() -> None:
    """Move everything loaded so far (modules, the solver's compiled code, the model) out of
    the garbage collector's way: a run's collections then walk only what the run made
    (a full collection over numba's objects costs milliseconds, as much as the steps)."""
    gc.collect()
    gc.freeze()


def warm_up_step(model) -> None:
    """``warm_up`` of ``compile_engine(model)``."""
    warm_up(lambda: compile_engine(model))


def prepare_engine(model, engine: str, rig: Path) -> tuple:
    """(``model`` with the engine its run starts on, the run's ``Runner.upgrade`` check or
    None) for ``engine``, one of ENGINES, the compiled step loaded or built (module
    docstring); ``rig`` is the rig file a background build compiles with."""
    numpy, compiled = model.with_options(engine="numpy"), model.with_options(engine="compiled")
    if engine == "numpy":
        warm_up(lambda: first_step(numpy), COMPILING_NUMPY, NUMPY_READY)
        chosen, upgrade = numpy, None
    elif compiled_ready():  # built: a slow first step is the rig's, not a compile
        warm_up(lambda: first_step(compiled), FIRST_STEP, "first step done")
        start_daemon(rig)
        chosen, upgrade = compiled, None
    elif engine == "compiled":
        warm_up_step(model)
        chosen, upgrade = compiled, None
    else:
        start_build(rig)
        click.echo(BUILDING, err=True)
        warm_up(lambda: first_step(numpy), COMPILING_NUMPY, NUMPY_READY)
        chosen, upgrade = numpy, compiled_ready
    freeze_loaded()
    return chosen, upgrade


def start_build(rig: Path) -> bool:
    """Start the background build with ``rig`` unless one is running (a lock beside the
    marker holds its process id); True when this call started it."""
    lock = marker().with_suffix(".building")
    if _running(lock):
        return False
    with contextlib.suppress(FileNotFoundError):
        lock.unlink()
    try:
        fd = os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
    except FileExistsError:  # another run took it first
        return False
    except OSError:  # no place for a lock: build anyway
        fd = None
    child = subprocess.Popen(
        [sys.executable, "-m", "puppetcli.run.warmup", str(Path(rig).resolve())],
        stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        start_new_session=True,
    )  # fmt: skip
    if fd is not None:
        os.write(fd, str(child.pid).encode())
        os.close(fd)
    return True


def _running(lock: Path) -> bool:
    """A build holds ``lock``: the lock names a live process."""
    try:
        pid = int(lock.read_text() or "0")
    except (OSError, ValueError):
        return False
    if pid <= 0:
        return lock.exists() and time.time() - lock.stat().st_mtime < 5.0  # pid not written yet
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _build(rig: str) -> None:
    """The background build (``start_build``): compile with the rig, then drop the lock."""
    from puppetcli.rig.load import load_rig
    from solver.model import build_model

    try:
        compile_engine(build_model(load_rig(Path(rig))))
    finally:
        with contextlib.suppress(OSError):
            marker().with_suffix(".building").unlink()


if __name__ == "__main__":
    _build(sys.argv[1])
