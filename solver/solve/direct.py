"""Exact solve of a two-sided row table: (A + diag(comp)) λ = −(J v_free + bias).

Q = A + diag(comp) is symmetric positive definite whenever every row touches a
movable body and the rows are independent (always true for a tree of ball
joints with compliant rheology rows), so a Cholesky factorisation is used, with
a least-squares fallback for degenerate input.
"""

from __future__ import annotations

import numpy as np

from solver.rows.table import Rows
from solver.solve.response import dense_system


def solve_spd(q: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Q⁻¹ rhs for a symmetric positive definite Q (least squares if it is not)."""
    import scipy.linalg  # on use: the compiled step never needs it, and it costs ~0.3 s to import

    try:
        return scipy.linalg.cho_solve(scipy.linalg.cho_factor(q), rhs)
    except np.linalg.LinAlgError:
        return np.linalg.lstsq(q, rhs, rcond=None)[0]


def direct_solve(
    rows: Rows, resp: tuple[np.ndarray, np.ndarray], vel_free: np.ndarray, rounds: int = 20
) -> tuple[np.ndarray, float, bool]:
    """(λ, residual, ok) for rows with lo < 0 < hi (box-bounded, no friction).

    Primal active set on the box-QP min ½λᵀQλ + cᵀλ: rows whose force leaves its box
    (a grip at its force limit) are pinned at that bound and the rest re-solved; a
    pinned row is released when its residual r = Qλ + c says it no longer pushes
    against the bound (r > 0 at hi, r < 0 at lo).  ok is False when the set did not
    settle within ``rounds``.  residual = max |r| over the free rows.
    """
    q, c = dense_system(rows, resp, vel_free)
    n = len(c)
    at_lo, at_hi = np.zeros(n, dtype=bool), np.zeros(n, dtype=bool)
    for _ in range(rounds):
        lam = _solve_with_pinned(q, c, rows, at_lo, at_hi)
        r = q @ lam + c
        release = (at_hi & (r > 0.0)) | (at_lo & (r < 0.0))
        leave_lo, leave_hi = ~(at_lo | at_hi) & (lam < rows.lo), ~(at_lo | at_hi) & (lam > rows.hi)
        if not (release.any() or leave_lo.any() or leave_hi.any()):
            free = ~(at_lo | at_hi)
            return lam, float(np.max(np.abs(r[free]), initial=0.0)), True
        at_lo = (at_lo & ~release) | leave_lo
        at_hi = (at_hi & ~release) | leave_hi
    return np.clip(lam, rows.lo, rows.hi), float("inf"), False


def _solve_with_pinned(
    q: np.ndarray, c: np.ndarray, rows: Rows, at_lo: np.ndarray, at_hi: np.ndarray
) -> np.ndarray:
    """λ with pinned rows at their bound and the free rows solving their equations."""
    lam = np.where(at_lo, rows.lo, np.where(at_hi, rows.hi, 0.0))
    pinned = at_lo | at_hi
    free = np.flatnonzero(~pinned)
    if len(free):
        rhs = -(c[free] + q[np.ix_(free, np.flatnonzero(pinned))] @ lam[pinned])
        lam[free] = solve_spd(q[np.ix_(free, free)], rhs)
    return lam
