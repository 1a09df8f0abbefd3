"""Slow dense reference solver of the mixed LCP, for tests and benchmarks.

The row problem r = Qλ + c, lo ≤ λ ≤ hi with complementarity is the optimality
condition of the box-constrained QP  min ½λᵀQλ + cᵀλ  (Q symmetric PSD).
Writing Q = LLᵀ (after a tiny ridge that makes it definite), the QP is the
bounded least-squares problem min ½‖Lᵀλ + L⁻¹c‖², solved exactly by the
active-set BVLS method of scipy.optimize.lsq_linear.  Friction bounds ±μλ_n
depend on the solution; they are found by a damped fixed-point iteration on
λ_n (plain substitution can oscillate between two friction states).
This shares no code with the PGS solver.
"""

from __future__ import annotations

import numpy as np


def _box_qp(q: np.ndarray, c: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Exact minimiser of ½λᵀQλ + cᵀλ over lo ≤ λ ≤ hi (variables with lo == hi fixed)."""
    import scipy.linalg  # on use: importing scipy's costs ~0.3 s a run that does not need it
    import scipy.optimize

    lam = np.where(np.isfinite(lo), lo, 0.0)
    free = hi - lo > 0.0
    lam[~free] = lo[~free]
    if not free.any():
        return lam
    f = np.flatnonzero(free)
    qf = q[np.ix_(f, f)]
    cf = c[f] + q[np.ix_(f, np.flatnonzero(~free))] @ lam[~free]
    ridge = 1e-13 * max(1.0, float(np.max(np.abs(np.diag(qf)))))
    chol = scipy.linalg.cholesky(qf + ridge * np.eye(len(f)), lower=True)
    rhs = -scipy.linalg.solve_triangular(chol, cf, lower=True)
    res = scipy.optimize.lsq_linear(
        chol.T, rhs, bounds=(lo[f], hi[f]), method="bvls", tol=1e-15, max_iter=10000
    )
    lam[f] = res.x
    return lam


def reference_solve(
    q: np.ndarray,
    c: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    fric_of: np.ndarray,
    mu: np.ndarray,
    max_rounds: int = 500,
    tol: float = 1e-13,
) -> np.ndarray:
    """λ of the mixed LCP r = Qλ + c with friction rows bounded by ±μ·λ[fric_of]."""
    lo = lo.astype(float).copy()
    hi = hi.astype(float).copy()
    fr = np.flatnonzero(fric_of >= 0)
    lam = np.zeros(len(c))
    for _ in range(max_rounds):
        bound = mu[fr] * np.maximum(lam[fric_of[fr]], 0.0)
        lo[fr], hi[fr] = -bound, bound
        new = _box_qp(q, c, lo, hi)
        done = np.max(np.abs(new - lam), initial=0.0) <= tol * max(
            1.0, np.max(np.abs(new), initial=0.0)
        )
        lam = new
        if done or len(fr) == 0:
            break
    return lam
