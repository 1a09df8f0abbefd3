"""Exact solve of an equality-only row table: (A + diag(comp)) λ = −(J v_free + bias).

Q = A + diag(comp) is symmetric positive definite whenever every row touches a
movable body and the rows are independent (always true for a tree of ball
joints with compliant rheology rows), so a Cholesky factorisation is used, with
a least-squares fallback for degenerate input.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

from solver.response import dense_system
from solver.rows import Rows


def direct_solve(
    rows: Rows, resp: tuple[np.ndarray, np.ndarray], vel_free: np.ndarray
) -> tuple[np.ndarray, float]:
    """(λ, residual) for an equality-only table; residual = max |Qλ + c| (velocity units)."""
    q, c = dense_system(rows, resp, vel_free)
    try:
        lam = scipy.linalg.cho_solve(scipy.linalg.cho_factor(q), -c)
    except np.linalg.LinAlgError:
        lam = np.linalg.lstsq(q, -c, rcond=None)[0]
    residual = float(np.max(np.abs(q @ lam + c))) if len(c) else 0.0
    return lam, residual
