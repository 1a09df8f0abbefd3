"""The compiled step's build: numba compiles the solver once a machine (2-3 minutes) and
caches it; a finished build leaves a marker beside numba's cache of the step, named with
the stamp of the solver's sources (``solver.jit.fingerprint``), so an edit of the solver
makes it stale."""

from __future__ import annotations

import contextlib
from pathlib import Path

__all__ = ["compile_engine", "compiled_ready", "marker"]


def compile_engine(model) -> None:
    """One throwaway step of ``model`` from rest on each of its compiled engine's paths, in
    place (a run's steps), along a path (a batch of them) and to a new State (a step the
    stepper hands back), and the joint-space step's kernels: numba compiles or loads them
    now rather than in the middle of a run.  Marks the build done (``compiled_ready``)."""
    import numpy as np

    from solver.compiled.joint_sim import compile_kernels
    from solver.engine import Engine
    from solver.state import initial_state

    compile_kernels()  # the joint-space step's (solver.advance.joint_space), for any model
    engine = Engine(model.with_options(engine="compiled", joint_space=False))  # the rows'
    stepper = engine.stepper()
    stepper.advance()
    path = (np.zeros((1, 3)), np.tile([1.0, 0.0, 0.0, 0.0], (1, 1)), np.zeros((1, 3)))
    stepper.follow((*path, np.zeros((1, 3))), 0.0, None, np.empty((1, 9)))
    engine.step(initial_state(model))
    with contextlib.suppress(OSError):  # no place for it: later runs build again, harmlessly
        marker().touch()


def compiled_ready() -> bool:
    """The compiled step of the current solver sources is built (module docstring)."""
    return marker().exists()


def marker() -> Path:
    """The build's marker: beside numba's cache of the step, named by the sources' stamp."""
    from solver.compiled.kernel import step_kernel
    from solver.jit import fingerprint

    return Path(step_kernel._cache._cache_path) / f"puppetcli-built-{fingerprint()[:16]}"
