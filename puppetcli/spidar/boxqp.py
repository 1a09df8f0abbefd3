"""Box-constrained convex QP by a primal active-set method.

    minimise ½ xᵀQx − cᵀx   subject to  lo ≤ x ≤ hi,   Q symmetric positive definite.

The structure of Springhead's ``QuadProgram.h`` (K. Akahane, S. Hasegawa): each variable
is free or held at its lower or upper bound (the working set).  One iteration:

1. solve the equality problem on the free variables with the others at their bounds:
   Q_FF x_F = c_F − Q_FB x_B (Cholesky: Q_FF is positive definite);
2. if that point is feasible, move there; then check the multipliers of the held
   variables, g = Qx − c: a variable at its lower bound is optimal when g_i ≥ 0, at its
   upper bound when g_i ≤ 0.  If all hold, x is the exact optimum (KKT); otherwise
   release the worst offender and repeat;
3. otherwise step toward it until the first free variable hits a bound and hold it there.

Every iterate is feasible, so a capped run still returns usable tensions.  With Q
positive definite the objective falls strictly between working sets, so no working set
repeats and the method ends in finitely many iterations.  A warm start passes the last
solution and working set (the device re-solves a slightly changed problem each tick).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

__all__ = ["BoxQPResult", "solve_box_qp"]

AT_LOWER, FREE, AT_UPPER = -1, 0, 1


@dataclass(frozen=True)
class BoxQPResult:
    """x (n,): the solution (feasible even if not converged).  working (n,) int8: −1 at
    lower bound, 0 free, +1 at upper bound.  iterations: passes used.  converged: KKT met."""

    x: np.ndarray
    working: np.ndarray
    iterations: int
    converged: bool


@njit(cache=True)
def _cholesky_solve(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """x with a x = b for a small symmetric positive definite a (Cholesky, in place)."""
    n = len(b)
    for j in range(n):
        for k in range(j):
            a[j, j] -= a[j, k] * a[j, k]
        a[j, j] = np.sqrt(a[j, j])
        for i in range(j + 1, n):
            for k in range(j):
                a[i, j] -= a[i, k] * a[j, k]
            a[i, j] /= a[j, j]
    x = b.copy()
    for i in range(n):
        for k in range(i):
            x[i] -= a[i, k] * x[k]
        x[i] /= a[i, i]
    for i in range(n - 1, -1, -1):
        for k in range(i + 1, n):
            x[i] -= a[k, i] * x[k]
        x[i] /= a[i, i]
    return x


@njit(cache=True)
def _equality_point(q: np.ndarray, c: np.ndarray, x: np.ndarray, working: np.ndarray):
    """Minimiser over the free variables with the held ones fixed at x."""
    target = x.copy()
    free = np.flatnonzero(working == FREE)
    m = len(free)
    if m == 0:
        return target
    a, rhs = np.empty((m, m)), np.empty(m)
    for r in range(m):
        i = free[r]
        rhs[r] = c[i]
        for j in range(len(x)):
            if working[j] != FREE:
                rhs[r] -= q[i, j] * x[j]
        for s in range(m):
            a[r, s] = q[i, free[s]]
    sol = _cholesky_solve(a, rhs)
    for r in range(m):
        target[free[r]] = sol[r]
    return target


@njit(cache=True)
def _active_set(q, c, lo, hi, x, working, cap: int, scale: float) -> tuple[int, bool]:
    """The iterations of the module docstring on x and working (in place)."""
    n = len(c)
    for it in range(1, cap + 1):
        d = _equality_point(q, c, x, working) - x
        alpha, index, side = 1.0, -1, FREE
        for i in range(n):  # the largest feasible step (ratio test over the free variables)
            if working[i] != FREE or d[i] == 0.0:
                continue
            bound, kind = (lo[i], AT_LOWER) if d[i] < 0.0 else (hi[i], AT_UPPER)
            step = (bound - x[i]) / d[i]
            if step < alpha:
                alpha, index, side = max(step, 0.0), i, kind
        if index >= 0:
            x += alpha * d
            x[index] = lo[index] if side == AT_LOWER else hi[index]
            working[index] = side
            continue
        x[:] = np.minimum(np.maximum(x + d, lo), hi)
        g = q @ x - c
        worst, most = -1, -np.inf
        for i in range(n):
            v = -g[i] if working[i] == AT_LOWER else (g[i] if working[i] == AT_UPPER else 0.0)
            if v > most:
                worst, most = i, v
        if most <= scale:
            return it, True
        working[worst] = FREE
    return cap, False


def _start(
    lo: np.ndarray, hi: np.ndarray, x0: np.ndarray | None, working0: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray]:
    """A feasible start consistent with its working set (cold: everything at lo)."""
    working = np.full(len(lo), AT_LOWER, dtype=np.int8) if working0 is None else working0.copy()
    x = np.array(lo, dtype=float) if x0 is None else np.clip(x0, lo, hi)
    x[working == AT_LOWER] = lo[working == AT_LOWER]
    x[working == AT_UPPER] = hi[working == AT_UPPER]
    return x, working


def solve_box_qp(
    q: np.ndarray,
    c: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    x0: np.ndarray | None = None,
    working0: np.ndarray | None = None,
    max_iterations: int | None = None,
    tol: float = 1e-12,
) -> BoxQPResult:
    """Minimise ½ xᵀQx − cᵀx on lo ≤ x ≤ hi (see the module docstring).

    ``max_iterations`` None runs to convergence (capped at 50·n as a safety net);
    ``tol`` is relative to the problem's scale for the multiplier signs.  The iterations
    are compiled (numba): a live session solves one QP a physics step.
    """
    n = len(c)
    x, working = _start(lo, hi, x0, working0)
    cap = 50 * n if max_iterations is None else max_iterations
    scale = tol * (1.0 + float(np.max(np.abs(c))) + float(np.max(np.abs(q))) * float(np.max(hi)))
    q, c = np.ascontiguousarray(q, dtype=float), np.ascontiguousarray(c, dtype=float)
    lo, hi = np.ascontiguousarray(lo, dtype=float), np.ascontiguousarray(hi, dtype=float)
    iterations, converged = _active_set(q, c, lo, hi, x, working, cap, scale)
    return BoxQPResult(x, working, iterations, converged)
