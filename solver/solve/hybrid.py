"""Exact joints, iterated contacts: the mixed LCP reduced to the rows that need iterating.

Rows fall into three sets:

* X, solved exactly: the joints' rows (ball-joint anchors, rheology: no bounds), the
  grip's rows (box-bounded, compliant) while they are inside their bounds, and the
  *leaf* contacts while they push and stick: the contacts of a bone on the static world,
  their normal row and friction rows together (in the compiled solve each is a leaf of
  the joint forest, hung from its bone);
* P, pinned: grip rows at a force limit, their force fixed at the bound, and
  frictionless leaf contacts that would pull (λ fixed at 0);
* U, iterated: the other contacts (between bones), the leaf contacts that slide (and,
  with friction, those that did not push last step or slid then: ``iterated_first``), their
  friction and joint limits, except the *dormant* ones: one-sided rows that did not push
  last step (warm λ = 0) and ask for no push now (bias > 0: a speculative gap, a limit not
  yet reached), with their friction rows.

With r = Qλ + c (Q = A + diag(C), solver.solve.response.dense_system) and the pinned forces
folded into c, r_X = 0 holds exactly by λ_X = −Q_XX⁻¹ (c_X + Q_XU λ_U), which leaves

    r_U = S λ_U + s,   S = Q_UU − Q_UX Q_XX⁻¹ Q_XU,   s = c_U − Q_UX Q_XX⁻¹ c_X.

S is the Delassus operator of the iterated rows *through the joints*: a contact on a
light link sees the effective mass of the whole articulated body behind it, so projected
Gauss–Seidel on S (solver.solve.pgs.dense_pgs, warm-started, ``iterations`` sweeps) does not
stall on mass ratios along a chain as PGS on the whole table does, and the joints hold
to the accuracy of the elimination however few sweeps run.  S is small and dense.

After the solve the sets are checked, as in an active-set method: a dormant row with r < 0
(it would be crossed) wakes (into U, or X for a leaf contact), a free grip row or
frictionless leaf contact outside its box is pinned, a pinned one whose r no longer pushes
against its bound is freed, and a sticking leaf contact whose friction leaves its pyramid
(|λ_t| > μ λ_n), or that would pull (held in the tangent plane, the exact solve can pull
on a contact that sliding would keep pressed), slides: it is iterated for the rest of the
step (one way, so the sets cannot cycle); then the solve repeats (at most ``rounds``
times). Dormant rows left at λ = 0 with r ≥ 0 satisfy their complementarity exactly, so
skipping them changes nothing but the cost. When the sets settle every row's conditions
hold: the exact rows have r = 0 inside their bounds, the pinned ones sit at a bound they
push against, and PGS solves the rest.

This is the readable version; solver.compiled.fast does the same with the joint tree's
linear-time elimination in place of the dense Q_XX factorisation.
"""

from __future__ import annotations

import numpy as np

from solver.rows.table import KIND_CONTACT, KIND_GRIP, KIND_JOINT, KIND_RHEOLOGY, Rows
from solver.solve.direct import solve_spd
from solver.solve.pgs import dense_pgs
from solver.solve.response import dense_system

SLID = 0.99
"""A warm friction force at least this fraction of its pyramid's bound (μ times its normal's
warm force): the contact slid last step (``iterated_first``)."""


def equality_rows(rows: Rows) -> np.ndarray:
    """(n,) bool: the joints' rows (anchors and rheology), always solved exactly."""
    return (rows.kind == KIND_JOINT) | (rows.kind == KIND_RHEOLOGY)


def contact_of(rows: Rows) -> np.ndarray:
    """(n,) int: each friction row's normal row, every other row itself."""
    return np.where(rows.fric_of >= 0, rows.fric_of, np.arange(len(rows)))


def leaf_contacts(rows: Rows) -> np.ndarray:
    """(n,) bool: the rows (normal and friction) of the contacts against the static world
    (one side −1) whose rows all have a compliance to be eliminated with (every hard row
    has one once regularised): solved exactly while they push and stick."""
    own = contact_of(rows)
    static_side = (rows.body_a < 0) | (rows.body_b < 0)
    leaf = (rows.kind == KIND_CONTACT) & static_side
    np.logical_and.at(leaf, own, rows.comp > 0.0)
    return leaf[own]


def iterated_first(rows: Rows, lam0: np.ndarray) -> np.ndarray:
    """(n,) bool: the normal rows with friction rows that start the step iterated rather
    than in the forest: those that did not push last step (touching down: warm λ_n = 0)
    and those whose warm friction sat at its bound (it slid: |λ_t| ≥ SLID·μ·λ_n, which
    holds for λ_n = 0 too).  Either would most likely slide again, and finding that out in
    the forest costs a round."""
    own = contact_of(rows)
    at_bound = (rows.fric_of >= 0) & (np.abs(lam0) >= SLID * rows.mu * lam0[own])
    first = np.zeros(len(rows), bool)
    first[own[at_bound]] = True
    return first


def dormant_rows(rows: Rows, lam0: np.ndarray) -> np.ndarray:
    """(n,) bool: one-sided rows with λ0 = 0 and bias > 0, and the friction of those."""
    one_sided = (rows.lo == 0.0) & np.isinf(rows.hi) & (rows.fric_of < 0)
    normal = one_sided & (lam0 == 0.0) & (rows.bias > 0.0)
    return normal[contact_of(rows)]


def schur_system(q: np.ndarray, c: np.ndarray, exact: np.ndarray, it: np.ndarray) -> tuple:
    """(S, s, X, x0) over the rows ``it`` with the rows ``exact`` eliminated:
    X = Q_XX⁻¹ Q_XU, x0 = Q_XX⁻¹ c_X, so λ_X = −(x0 + X λ_U)."""
    e, u = np.flatnonzero(exact), np.flatnonzero(it)
    if len(e) == 0:
        return q[np.ix_(u, u)], c[u], np.zeros((0, len(u))), np.zeros(0)
    x = solve_spd(q[np.ix_(e, e)], np.column_stack((c[e], q[np.ix_(e, u)])))
    x0, xu = x[:, 0], x[:, 1:]
    s_mat = q[np.ix_(u, u)] - q[np.ix_(u, e)] @ xu
    return 0.5 * (s_mat + s_mat.T), c[u] - q[np.ix_(u, e)] @ x0, xu, x0


def _local_friction(rows: Rows, it: np.ndarray) -> np.ndarray:
    """fric_of of the rows ``it`` as indices into that subset (a friction row's normal is
    always in the same set: they wake and sleep together)."""
    u = np.flatnonzero(it)
    local = np.full(len(rows), -1, dtype=np.int64)
    local[u] = np.arange(len(u))
    return np.where(rows.fric_of[u] >= 0, local[np.maximum(rows.fric_of[u], 0)], -1)


def _round(rows, q, c, lam0, exact, it, pinned_lam, iterations, tol) -> tuple:
    """λ (with pinned rows at pinned_lam, NaN elsewhere), sweeps and residual of one solve."""
    pinned = ~np.isnan(pinned_lam)
    lam = np.where(pinned, pinned_lam, 0.0)
    c_eff = c + q[:, pinned] @ lam[pinned]
    s_mat, s_vec, xu, x0 = schur_system(q, c_eff, exact, it)
    lam_u, sweeps, residual = np.zeros(0), 0, 0.0
    if it.any():
        lam_u, sweeps, residual = dense_pgs(
            s_mat, s_vec, rows.lo[it], rows.hi[it], _local_friction(rows, it), rows.mu[it],
            lam0[it], iterations, tol,
        )  # fmt: skip
    lam[it] = lam_u
    lam[exact] = -(x0 + xu @ lam_u)
    return lam, sweeps, residual


def hybrid_solve(
    rows: Rows,
    resp: tuple[np.ndarray, np.ndarray],
    vel_free: np.ndarray,
    lam0: np.ndarray,
    iterations: int,
    tol: float = 1e-12,
    rounds: int = 20,
    skip_dormant: bool = True,
    leaves: bool = True,
) -> tuple[np.ndarray, int, float]:
    """(λ, sweeps, residual) (module docstring); sweeps and residual are those of the
    last round's PGS on S (0 when nothing is iterated).  ``skip_dormant`` False iterates
    the dormant rows too (the unskipped path, for measuring the skip); ``leaves`` False
    iterates the leaf contacts too (Options.leaf_contacts)."""
    q, c = dense_system(rows, resp, vel_free)
    joint, grip, leaf = equality_rows(rows), rows.kind == KIND_GRIP, leaf_contacts(rows) & leaves
    own = contact_of(rows)
    rubbing = np.zeros(len(rows), bool)  # normal rows with friction rows
    rubbing[own[rows.fric_of >= 0]] = True
    dormant = dormant_rows(rows, lam0) & ~grip & skip_dormant
    at_lo, at_hi = np.zeros(len(rows), bool), np.zeros(len(rows), bool)  # (a leaf: its normal)
    sliding = iterated_first(rows, lam0)  # leaf contacts iterated for the rest of the step
    for _ in range(rounds):
        pinned_lam = np.where(at_lo, rows.lo, np.where(at_hi, rows.hi, np.nan))
        stuck = leaf & ~sliding[own] & ~at_lo[own] & ~dormant
        exact = joint | (grip & ~at_lo & ~at_hi) | stuck
        it = ~joint & ~grip & ~dormant & (~leaf | sliding[own])
        lam, sweeps, residual = _round(rows, q, c, lam0, exact, it, pinned_lam, iterations, tol)
        r = q @ lam + c
        crossed = dormant & (rows.fric_of < 0) & (r < 0.0)
        woke = crossed[own]
        release = (at_hi & (r > 0.0)) | (at_lo & (r < 0.0))
        free = (grip & ~at_lo & ~at_hi) | (stuck & (rows.fric_of < 0))
        leave_lo, leave_hi = free & (lam < rows.lo) & ~rubbing, free & (lam > rows.hi)
        slip = stuck & (rows.fric_of >= 0) & (np.abs(lam) > rows.mu * lam[own])
        slides = free & (lam < rows.lo) & rubbing  # (held in the tangent, it would pull)
        slides[own[slip]] = True
        if not (woke.any() or release.any() or leave_lo.any() or leave_hi.any() or slides.any()):
            return lam, sweeps, residual
        sliding |= slides
        dormant &= ~woke
        at_lo, at_hi = (at_lo & ~release) | leave_lo, (at_hi & ~release) | leave_hi
    return np.clip(lam, rows.lo, rows.hi), sweeps, residual
