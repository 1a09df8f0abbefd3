"""A cycle counter readable from compiled code, for the step's stage profile.

``cycles()`` is LLVM's ``readcyclecounter`` (the time-stamp counter on x86-64): an
intrinsic, so code that calls it still caches on disk (a ctypes clock would pin a
function address into the cache).  Counts are converted to seconds by timing a known
interval against ``time.perf_counter`` (``seconds_per_cycle``).  Where the target has
no counter it reads 0 and the profile shows zeros.
"""

from __future__ import annotations

import time

from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

from solver.jit import kernel


@intrinsic
def _readcyclecounter(typingctx):
    def codegen(context, builder, signature, args):
        fnty = ir.FunctionType(ir.IntType(64), [])
        fn = cgutils.get_or_insert_function(builder.module, fnty, "llvm.readcyclecounter")
        return builder.call(fn, [])

    return types.int64(), codegen


@kernel()
def cycles():
    """The processor's cycle counter (int64)."""
    return _readcyclecounter()


def seconds_per_cycle(interval: float = 0.05) -> float:
    """Seconds per count of ``cycles`` over a busy-waited interval (0 without a counter)."""
    cycles()
    c0, t0 = cycles(), time.perf_counter()
    while time.perf_counter() - t0 < interval:
        pass
    c1, t1 = cycles(), time.perf_counter()
    return (t1 - t0) / (c1 - c0) if c1 > c0 else 0.0


@kernel()
def _reads(n):
    total = 0
    for _ in range(n):
        total += cycles() & 1
    return total


def counter_read_seconds(reads: int = 20000) -> float:
    """Seconds one ``cycles()`` costs, timed over a compiled loop of ``reads`` reads."""
    _reads(10)
    start = time.perf_counter()
    _reads(reads)
    return (time.perf_counter() - start) / reads


STAGES = (
    "setup (frames, inertia, substep test)",
    "free velocities",
    "joint rows (anchors, rheology, limits)",
    "collision and contact/grip rows",
    "regularisation",
    "solve (and the row responses it uses)",
    "integrate, project, monitor",
    "rheology update, warm keys, report",
)


"""Stages of the step's profile (``ws[10]``: cycles per stage, summed while iopt[7])."""


@kernel(error_model="numpy")
def tick(prof, on, stage, t0):
    """Add the cycles since t0 to ``stage`` when profiling; the new mark."""
    if not on:
        return t0
    t = cycles()
    prof[stage] += t - t0
    return t
