"""Keep numba's on-disk cache of the compiled step consistent with its sources.

numba invalidates a cached function only when *its own* file changes; the step kernel
inlines functions from every module of this package, from ``solver.pgs`` (the PGS
kernels) and ``solver.substep`` (the substep criterion), and freezes constants read
from ``solver.rows`` (row kinds, key layout), ``solver.integrate``, ``solver.direct``,
``solver.hybrid`` and ``solver.stabilize`` (passes, rounds, tolerances), so an edit
there would leave a stale kernel in the cache.
``ensure_fresh_cache`` fingerprints all of those sources (not this package's
Python-only modules, ``PYTHON_ONLY``: no compiled function is built from them, so editing
the ``fast_step`` wrapper does not recompile every kernel) and, when the fingerprint
changed, deletes this package's cached kernels
(``__pycache__/*.nbi``/``*.nbc``) so numba recompiles them.  Cache locations other than
``__pycache__`` (NUMBA_CACHE_DIR) are left to the user.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

HERE = Path(__file__).resolve().parent
NUMPY_SOURCES = (
    "pgs.py", "rows.py", "integrate.py", "direct.py", "stabilize.py", "substep.py", "hybrid.py",
    "sleep.py",
)  # fmt: skip
SOURCES = tuple(HERE.parent / name for name in NUMPY_SOURCES)
PYTHON_ONLY = ("__init__.py", "bench.py", "cache.py", "pack.py", "sim.py")
"""Modules with no compiled code that no compiled module imports (tests/solver/test_flat.py)."""


def fingerprint() -> str:
    """SHA-256 over the names and contents of every source the kernels are built from."""
    digest = hashlib.sha256()
    kernels = sorted(path for path in HERE.glob("*.py") if path.name not in PYTHON_ONLY)
    for path in kernels + list(SOURCES):
        digest.update(path.name.encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()


def ensure_fresh_cache() -> None:
    """Drop this package's numba cache files when any kernel source changed."""
    cache = HERE / "__pycache__"
    stamp = cache / "kernels.stamp"
    current = fingerprint()
    try:
        if stamp.read_text() == current:
            return
    except OSError:
        pass
    try:
        cache.mkdir(exist_ok=True)
        for path in list(cache.glob("*.nbi")) + list(cache.glob("*.nbc")):
            path.unlink(missing_ok=True)
        tmp = cache / f"kernels.stamp.{os.getpid()}"
        tmp.write_text(current)
        tmp.replace(stamp)
    except OSError:
        pass  # a read-only install: numba then caches elsewhere, or not at all
