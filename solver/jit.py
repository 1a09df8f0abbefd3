"""``kernel``: the decorator of every compiled function of the solver, and its cache.

``kernel(**options)`` is ``numba.njit(cache=True, **options)``: compiled once per
machine, then loaded from numba's on-disk cache (``__pycache__`` beside each source).

numba judges a cached function fresh by its *own* file alone, but the step inlines
functions from many modules and freezes constants read from numpy modules (row kinds,
passes, tolerances), so an edit elsewhere could leave a stale kernel in the cache.  The
cache locator here stamps every cached function with a hash of all of the solver's
sources the kernels are built from (every module but ``PYTHON_ONLY``), so numba finds a
stale index and recompiles instead.  Nothing is written or deleted when this module is
imported: numba reads and writes its cache when it compiles or loads a function.
Cache locations other than ``__pycache__`` (``NUMBA_CACHE_DIR``) are numba's own.
"""

from __future__ import annotations

import functools
import hashlib
from pathlib import Path

from numba import njit
from numba.core.caching import CacheImpl, InTreeCacheLocator

ROOT = Path(__file__).resolve().parent
PYTHON_ONLY = (
    "pipeline.py", "engine.py", "compiled/fast.py", "compiled/pack.py", "compiled/sim.py",
    "compiled/joint_sim.py",
)  # fmt: skip
"""Modules with no compiled function that no compiled function's module imports
(tests/solver/test_jit.py): editing them does not recompile the kernels."""


def kernel(**options):
    """numba.njit(cache=True, **options), cached under the solver's source stamp."""
    return njit(cache=True, **options)


@functools.cache
def fingerprint() -> str:
    """SHA-256 over the names and contents of every source the kernels are built from
    (computed once a process: the sources do not change under a running solver)."""
    digest = hashlib.sha256()
    for path in sorted(ROOT.rglob("*.py")):
        name = path.relative_to(ROOT).as_posix()
        if name not in PYTHON_ONLY:
            digest.update(name.encode())
            digest.update(path.read_bytes())
    return digest.hexdigest()


class SolverCacheLocator(InTreeCacheLocator):
    """numba's in-tree cache for the solver's functions, stamped with ``fingerprint``."""

    @classmethod
    def from_function(cls, py_func, py_file):
        if not Path(py_file).resolve().is_relative_to(ROOT):
            return None  # someone else's function: numba's own locators
        return super().from_function(py_func, py_file)

    def get_source_stamp(self):
        return (super().get_source_stamp(), fingerprint())


if SolverCacheLocator not in CacheImpl._locator_classes:
    CacheImpl._locator_classes.insert(0, SolverCacheLocator)
