"""Box-constrained convex QP by a primal active-set method.

    minimise ½ xᵀQx − cᵀx   subject to  lo ≤ x ≤ hi,   Q symmetric positive definite.

The structure of Springhead's ``QuadProgram.h`` (K. Akahane, S. Hasegawa): each variable
is free or held at its lower or upper bound (the working set).  One iteration:

1. solve the equality problem on the free variables with the others at their bounds:
   Q_FF x_F = c_F − Q_FB x_B;
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


def _equality_point(q: np.ndarray, c: np.ndarray, x: np.ndarray, free: np.ndarray) -> np.ndarray:
    """Minimiser over the free variables with the held ones fixed at x."""
    target = x.copy()
    if np.any(free):
        held = ~free
        rhs = c[free] - q[np.ix_(free, held)] @ x[held]
        target[free] = np.linalg.solve(q[np.ix_(free, free)], rhs)
    return target


def _ratio_step(
    x: np.ndarray, d: np.ndarray, lo: np.ndarray, hi: np.ndarray, free: np.ndarray
) -> tuple[float, int, int]:
    """Largest step α ≤ 1 along d keeping x feasible: (α, blocking index or −1, its bound)."""
    alpha, index, bound = 1.0, -1, FREE
    for i in np.nonzero(free)[0]:
        if d[i] < 0.0:
            step, side = (lo[i] - x[i]) / d[i], AT_LOWER
        elif d[i] > 0.0:
            step, side = (hi[i] - x[i]) / d[i], AT_UPPER
        else:
            continue
        if step < alpha:
            alpha, index, bound = max(step, 0.0), int(i), side
    return alpha, index, bound


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
    ``tol`` is relative to the problem's scale for the multiplier signs.
    """
    n = len(c)
    x, working = _start(lo, hi, x0, working0)
    cap = 50 * n if max_iterations is None else max_iterations
    scale = tol * (1.0 + float(np.max(np.abs(c))) + float(np.max(np.abs(q))) * float(np.max(hi)))
    for it in range(1, cap + 1):
        free = working == FREE
        d = _equality_point(q, c, x, free) - x
        alpha, index, side = _ratio_step(x, d, lo, hi, free)
        if index >= 0:
            x = x + alpha * d
            x[index] = lo[index] if side == AT_LOWER else hi[index]
            working[index] = side
            continue
        x = np.clip(x + d, lo, hi)
        g = q @ x - c
        violation = np.where(working == AT_LOWER, -g, np.where(working == AT_UPPER, g, 0.0))
        worst = int(np.argmax(violation))
        if violation[worst] <= scale:
            return BoxQPResult(x, working, it, True)
        working[worst] = FREE
    return BoxQPResult(x, working, cap, False)
