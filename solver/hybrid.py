"""Exact joints, iterated contacts: the mixed LCP reduced to its bounded rows.

The rows split into E, the joints' equality rows (ball-joint anchors and rheology, which
have no bounds), and U, every other row (contacts, friction, limits, the grip: all bounded).  With
r = Qλ + c (Q = A + diag(C), solver.response.dense_system), r_E = 0 holds exactly by

    λ_E = −Q_EE⁻¹ (c_E + Q_EU λ_U),

which leaves the LCP of the U rows alone,

    r_U = S λ_U + s,   S = Q_UU − Q_UE Q_EE⁻¹ Q_EU,   s = c_U − Q_UE Q_EE⁻¹ c_E.

S is the Delassus operator of the bounded rows *through the joints*: a contact on a
light link sees the effective mass of the whole articulated body behind it, so the
projected Gauss–Seidel on S (solver.pgs.dense_pgs, warm-started) does not stall on mass
ratios along a chain the way PGS on the full row table does, and the joints hold to
the accuracy of the Cholesky solve however few sweeps run.  S is small (the bounded
rows of a doll: a few contacts and limits), dense and symmetric positive definite
(every row is regularised).

This is the readable version; solver.fast does the same with the joint tree's
linear-time elimination in place of the dense Q_EE factorisation.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

from solver.pgs import dense_pgs
from solver.response import dense_system
from solver.rows import KIND_JOINT, KIND_RHEOLOGY, Rows


def equality_rows(rows: Rows) -> np.ndarray:
    """(n,) bool: the joints' rows (anchors and rheology), solved exactly."""
    return (rows.kind == KIND_JOINT) | (rows.kind == KIND_RHEOLOGY)


def _solve_spd(q: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    try:
        return scipy.linalg.cho_solve(scipy.linalg.cho_factor(q), rhs)
    except np.linalg.LinAlgError:
        return np.linalg.lstsq(q, rhs, rcond=None)[0]


def schur_system(q: np.ndarray, c: np.ndarray, eq: np.ndarray) -> tuple:
    """(S, s, X, x0) with X = Q_EE⁻¹ Q_EU and x0 = Q_EE⁻¹ c_E, so λ_E = −(x0 + X λ_U)."""
    e, u = np.flatnonzero(eq), np.flatnonzero(~eq)
    if len(e) == 0:
        return q, c, np.zeros((0, len(u))), np.zeros(0)
    x = _solve_spd(q[np.ix_(e, e)], np.column_stack((c[e], q[np.ix_(e, u)])))
    x0, xu = x[:, 0], x[:, 1:]
    s_mat = q[np.ix_(u, u)] - q[np.ix_(u, e)] @ xu
    return 0.5 * (s_mat + s_mat.T), c[u] - q[np.ix_(u, e)] @ x0, xu, x0


def hybrid_solve(
    rows: Rows,
    resp: tuple[np.ndarray, np.ndarray],
    vel_free: np.ndarray,
    lam0: np.ndarray,
    iterations: int,
    tol: float = 1e-12,
) -> tuple[np.ndarray, int, float]:
    """(λ, sweeps, residual): E rows exact, U rows by PGS on S from lam0 (module
    docstring).  residual: that of the PGS on S (solver.pgs.dense_pgs); the E rows hold
    to the rounding of the Cholesky solve."""
    q, c = dense_system(rows, resp, vel_free)
    eq = equality_rows(rows)
    s_mat, s_vec, xu, x0 = schur_system(q, c, eq)
    u = np.flatnonzero(~eq)
    local = np.full(len(rows), -1, dtype=np.int64)
    local[u] = np.arange(len(u))
    fric = np.where(rows.fric_of[u] >= 0, local[np.maximum(rows.fric_of[u], 0)], -1)
    lam_u, sweeps, residual = np.zeros(0), 0, 0.0
    if len(u):
        lam_u, sweeps, residual = dense_pgs(
            s_mat, s_vec, rows.lo[u], rows.hi[u], fric, rows.mu[u], lam0[u], iterations, tol
        )
    lam = np.zeros(len(rows))
    lam[u] = lam_u
    lam[eq] = -(x0 + xu @ lam_u)
    return lam, sweeps, residual
