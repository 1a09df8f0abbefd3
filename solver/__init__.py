"""The simulator: ``solver.Engine(model)`` and ``solver.step`` (solver.engine).

OPENBLAS_NUM_THREADS is set before numpy loads: the matrices here are small (≤ a few
hundred rows), where OpenBLAS's threads cost more than they give (2–8× slower Cholesky
on 2 cores, with numba loaded).  A user's own setting wins.
"""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

_ENTRY = ("ENGINES", "Engine", "NumpyStepper", "step")


def __getattr__(name: str):
    """The entry's names, imported on first use (``solver.model`` alone needs no numba)."""
    if name in _ENTRY:
        from solver import engine

        return getattr(engine, name)
    raise AttributeError(f"module 'solver' has no attribute {name!r}")
