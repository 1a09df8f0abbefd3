"""Compiled hybrid solve (solver.hybrid): joints exact by the tree, bounded rows by PGS.

The equality rows E are the joint nodes' rows (anchors, then rheology: the first ``ne``
rows of the table); the bounded rows U (limits, contacts, friction, grip) follow.  With
the forest factored once (solver.fast.tree.tree_factor), each U row r costs one
substitution: the body right-hand side J_rᵀ gives the velocity change of every body per
unit λ_r with the joints holding, so the column S[:, r] = J_U y⁽ʳ⁾ + C_r e_r of the
Delassus operator through the joints.  The base substitution (U forces zero) gives
s = J_U (v_free + y⁽⁰⁾) + β_U.  After PGS on S (solver.pgs.dense_pgs), one more
substitution with the U forces folded into v_free gives λ_E and the velocities.
Cost: (|U| + 2) substitutions of O(nodes) 6×6 blocks and an O(|U|²) PGS sweep.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from solver.fast.post import apply_rows
from solver.fast.tree import (
    init_nodes,
    init_rhs,
    node_rows,
    row_velocity,
    tree_factor,
    tree_substitute,
)
from solver.pgs import dense_pgs


@njit(cache=True, error_model="numpy")
def _body_dot(rw, r, x, movable):
    """J_r · x over the movable sides of row r (x (nodes, 6), body nodes first)."""
    a, b = rw[0][r], rw[1][r]
    s = 0.0
    if a >= 0 and movable[a] > 0.0:
        for k in range(6):
            s += rw[2][r, k] * x[a, k]
    if b >= 0 and movable[b] > 0.0:
        for k in range(6):
            s += rw[3][r, k] * x[b, k]
    return s


@njit(cache=True, error_model="numpy")
def _mark_path(body, parent, movable, mark, tag):
    """mark[node] = tag on the path from a movable body to its root."""
    if body < 0 or movable[body] <= 0.0:
        return
    node = body
    while node >= 0 and mark[node] != tag:
        mark[node] = tag
        node = parent[node]


@njit(cache=True, error_model="numpy")
def _schur(rw, ne, n, seq, nseq, parent, nb, size, tw, movable, x):
    """S (nu, nu) column by column (module docstring).  A column's right-hand side sits on
    two bodies, and S needs the solution only at the U rows' bodies: each substitution runs
    forward on the two bodies' root paths and backward on the U bodies' root paths."""
    nu = n - ne
    s_mat = np.empty((nu, nu))
    path, needed = np.zeros(len(parent), np.int64), np.zeros(len(parent), np.int64)
    for i in range(ne, n):
        _mark_path(rw[0][i], parent, movable, needed, 1)
        _mark_path(rw[1][i], parent, movable, needed, 1)
    for q in range(nseq):
        i = seq[q]
        if needed[i] == 1:
            for c in range(6):
                x[i, c] = 0.0
    for k in range(nu):
        r = ne + k
        _mark_path(rw[0][r], parent, movable, path, k + 1)
        _mark_path(rw[1][r], parent, movable, path, k + 1)
        for q in range(nseq):
            i = seq[q]
            if path[i] == k + 1 or needed[i] == 1:
                for c in range(6):
                    x[i, c] = 0.0
        a, b = rw[0][r], rw[1][r]
        if a >= 0 and movable[a] > 0.0:
            for c in range(6):
                x[a, c] += rw[2][r, c]
        if b >= 0 and movable[b] > 0.0:
            for c in range(6):
                x[b, c] += rw[3][r, c]
        tree_substitute(seq, nseq, parent, nb, size, tw, x, path, k + 1, needed, 1)
        for i in range(nu):
            s_mat[i, k] = _body_dot(rw, ne + i, x, movable)
        s_mat[k, k] += rw[6][r]
    for i in range(nu):
        for k in range(i):
            s_mat[i, k] = s_mat[k, i] = 0.5 * (s_mat[i, k] + s_mat[k, i])
    return s_mat


@njit(cache=True, error_model="numpy")
def _solve_joints(seq, nseq, parent, nb, rw, vel, rows, size, tw, movable, lam, out):
    """λ_E and out = vel + y for the factored forest with v_free replaced by ``vel``."""
    x = tw[2]
    init_rhs(seq, nseq, nb, rw, vel, rows, size, x)
    every = np.zeros(len(parent), np.int64)
    tree_substitute(seq, nseq, parent, nb, size, tw, x, every, 0, every, 0)
    for b in range(nb):
        for k in range(6):
            out[b, k] = vel[b, k]
    for q in range(nseq):
        i = seq[q]
        if i < nb:
            if movable[i] > 0.0:
                for k in range(6):
                    out[i, k] += x[i, k]
        else:
            for k in range(size[i]):
                lam[rows[i, k]] = x[i, k]


@njit(cache=True, error_model="numpy")
def hybrid_solve(m, tree, ws, opt, rw, n, ne, vel_free, lam0, iterations):
    """(ok, λ, v, sweeps, residual); ok False when the joint system is degenerate."""
    order, parent, rheo_start, _, seq, rows, size, tw = tree
    nb = len(vel_free)
    movable = m[16]
    nseq = 0
    for i in order:
        seq[nseq] = i
        nseq += 1
        size[i] = node_rows(i, nb, rheo_start, rows[i])
    lam = np.zeros(n)
    vel = np.empty_like(vel_free)
    init_nodes(seq, nseq, nb, rw, vel_free, opt[0], m[15], ws[7], rows, size, tw[0], tw[2])
    if not tree_factor(seq, nseq, parent, nb, rw, rows, size, tw):
        return False, lam, vel, 0, 0.0
    nu = n - ne
    _solve_joints(seq, nseq, parent, nb, rw, vel_free, rows, size, tw, movable, lam, vel)
    if nu == 0:
        return True, lam, vel, 0, 0.0
    s_vec = np.empty(nu)
    lo, hi, fric, mu = np.empty(nu), np.empty(nu), np.empty(nu, np.int64), np.empty(nu)
    for i in range(nu):
        r = ne + i
        s_vec[i] = row_velocity(rw, r, vel) + rw[7][r]
        lo[i], hi[i], mu[i] = rw[4][r], rw[5][r], rw[9][r]
        fric[i] = rw[8][r] - ne if rw[8][r] >= 0 else -1
    s_mat = _schur(rw, ne, n, seq, nseq, parent, nb, size, tw, movable, tw[2])
    lam_u, sweeps, residual = dense_pgs(
        s_mat, s_vec, lo, hi, fric, mu, lam0[ne:n].copy(), iterations, 1e-12
    )
    chosen = np.zeros(n, dtype=np.bool_)
    for i in range(nu):
        lam[ne + i] = lam_u[i]
        chosen[ne + i] = True
    pushed = vel_free.copy()
    apply_rows(rw, chosen, ws[1], ws[2], lam, pushed)
    _solve_joints(seq, nseq, parent, nb, rw, pushed, rows, size, tw, movable, lam, vel)
    return True, lam, vel, sweeps, residual
