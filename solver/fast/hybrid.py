"""Compiled hybrid solve (solver.hybrid): joints and grip exact by the tree, the active
bounded rows by PGS on their Schur complement, dormant rows checked afterwards.

The joints' rows are the first ``ne`` rows of the table; grip rows are rows grip0 …
grip0 + ngrip − 1 (a node of the forest while inside their bounds, pinned at a bound
otherwise, as in the direct solve); every other row is iterated (U) or dormant (solver.
hybrid.dormant_rows).  With the forest factored once per round (tree_factor), each U
row r costs one substitution: the body right-hand side J_rᵀ gives every body's velocity
change per unit λ_r with the joints and grip holding, so S[:, r] = J_U y⁽ʳ⁾ + C_r e_r; it
runs forward only on the root paths of r's bodies and backward only on those of the U
rows' bodies.  The base substitution (U forces zero) gives s = J_U (v_free + y⁽⁰⁾) + β_U.
After PGS on S (solver.pgs.dense_pgs), one more substitution with the U forces folded
into v_free gives λ of the exact rows and the velocities.  Without U rows one
substitution does it all.
"""

from __future__ import annotations

import inspect

import numpy as np
from numba import njit

from solver import hybrid
from solver.fast.post import apply_rows
from solver.fast.tree import (
    ALL,
    backward_pass,
    forest_sequence,
    forward_pass,
    init_nodes,
    init_rhs,
    row_velocity,
    tree_factor,
    tree_substitute,
)
from solver.pgs import dense_pgs
from solver.rows import KIND_GRIP

ROUNDS = inspect.signature(hybrid.hybrid_solve).parameters["rounds"].default


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
def _schur(rw, its, nu, seq, nseq, parent, nb, size, tw, movable, x):
    """S (nu, nu) over the rows its[:nu], column by column (module docstring)."""
    s_mat = np.empty((nu, nu))
    path, needed = np.zeros(len(parent), np.int64), np.zeros(len(parent), np.int64)
    for i in range(nu):
        _mark_path(rw[0][its[i]], parent, movable, needed, 1)
        _mark_path(rw[1][its[i]], parent, movable, needed, 1)
    for k in range(nu):
        r = its[k]
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
            s_mat[i, k] = _body_dot(rw, its[i], x, movable)
        s_mat[k, k] += rw[6][r]
    for i in range(nu):
        for k in range(i):
            s_mat[i, k] = s_mat[k, i] = 0.5 * (s_mat[i, k] + s_mat[k, i])
    return s_mat


@njit(cache=True, error_model="numpy", _nrt=False)
def _solve_exact(seq, nseq, parent, nb, movable, rows, size, tw, vel, lam, out, forward):
    """λ of the forest's rows and out = vel + y, with v_free replaced by ``vel``, from
    the right-hand sides of ``vel`` in tw[2] (init_rhs made them; forward False: init_nodes
    made them and tree_factor has run the forward pass)."""
    x = tw[2]
    if forward:
        forward_pass(seq, nseq, parent, nb, size, tw, x, parent, ALL)
    backward_pass(seq, nseq, parent, nb, size, tw, x, parent, ALL)
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
def dormant_rows(rw, n, lam0):
    """solver.hybrid.dormant_rows on the table's first n rows."""
    out = np.zeros(n, dtype=np.bool_)
    lo, hi, bias, fric = rw[4], rw[5], rw[7], rw[8]  # (not rw[k] inside and/or: see _update_sets)
    for i in range(n):
        if lo[i] == 0.0 and hi[i] == np.inf and fric[i] < 0:
            out[i] = lam0[i] == 0.0 and bias[i] > 0.0
    for i in range(n):
        if fric[i] >= 0:
            out[i] = out[fric[i]]
    return out


@njit(cache=True, error_model="numpy")
def _iterate(rw, its, nu, s_vec, lam0, iterations):
    """PGS on S's rows: bounds, friction (indices local to its) and warm start."""
    lo, hi, fric, mu, start = (np.empty(nu), np.empty(nu), np.full(nu, -1, np.int64),
                               np.empty(nu), np.empty(nu))  # fmt: skip
    local = np.full(len(rw[0]), -1, np.int64)
    for i in range(nu):
        local[its[i]] = i
    for i in range(nu):
        r = its[i]
        lo[i], hi[i], mu[i], start[i] = rw[4][r], rw[5][r], rw[9][r], lam0[r]
        if rw[8][r] >= 0:
            fric[i] = local[rw[8][r]]
    return lo, hi, fric, mu, start


@njit(cache=True, error_model="numpy", inline="always")
def _round(bw, tree, h, rw, n, lam, vel_p, its, nu, grips, lam0, iters, asleep):
    """One solve with the current sets: (ok, v, sweeps, residual); fills λ.
    bw: the solvers' model arrays (solver.fast.kernel.solve); grips = (free grip rows,
    their count, the gripped body)."""
    _, parent, _, _, seq, rows, size, tw = tree
    joint_bone, mass, movable, resp_a, resp_b, _, inertia_w = bw
    nb = len(vel_p)
    free_grip, ngrip, body = grips
    nseq = forest_sequence(tree, nb, movable, free_grip, ngrip, body, asleep, joint_bone)
    init_nodes(seq, nseq, nb, rw, vel_p, h, mass, inertia_w, rows, size, tw[0], tw[2])
    vel = np.empty_like(vel_p)
    if not tree_factor(seq, nseq, parent, nb, rw, rows, size, tw):
        return False, vel, 0, 0.0
    _solve_exact(seq, nseq, parent, nb, movable, rows, size, tw, vel_p, lam, vel, False)
    if nu == 0:
        return True, vel, 0, 0.0
    s_vec = np.empty(nu)
    for i in range(nu):
        s_vec[i] = row_velocity(rw, its[i], vel) + rw[7][its[i]]
    s_mat = _schur(rw, its, nu, seq, nseq, parent, nb, size, tw, movable, tw[2])
    lo, hi, fric, mu, start = _iterate(rw, its, nu, s_vec, lam0, iters)
    lam_u, sweeps, residual = dense_pgs(s_mat, s_vec, lo, hi, fric, mu, start, iters, 1e-12)
    chosen = np.zeros(n, dtype=np.bool_)
    for i in range(nu):
        lam[its[i]] = lam_u[i]
        chosen[its[i]] = True
    pushed = vel_p.copy()
    apply_rows(rw, chosen, resp_a, resp_b, lam, pushed)
    init_rhs(seq, nseq, nb, rw, pushed, rows, size, tw[2])
    _solve_exact(seq, nseq, parent, nb, movable, rows, size, tw, pushed, lam, vel, True)
    return True, vel, sweeps, residual


@njit(cache=True, error_model="numpy", inline="always")
def hybrid_solve(bw, tree, h, rw, n, ne, vel_free, lam0, iterations, grip, skip, asleep):
    """(ok, λ, v, sweeps, residual) as solver.hybrid.hybrid_solve; ok False when the
    exact system is degenerate; bw: the solvers' model arrays (solver.fast.kernel.solve);
    h: the step; ``skip``: leave dormant rows out of the iteration; asleep (nb,) bool:
    sleeping bodies (their islands are not in the forest)."""
    grip0, ngrip, body = grip
    resp_a, resp_b = bw[3], bw[4]
    dormant = dormant_rows(rw, n, lam0) if skip else np.zeros(n, dtype=np.bool_)
    at_lo, at_hi = np.zeros(n, dtype=np.bool_), np.zeros(n, dtype=np.bool_)
    its, free_grip = np.empty(n, np.int64), np.empty(6, np.int64)
    lam = np.zeros(n)
    lo, hi, kind = rw[4], rw[5], rw[11]
    vel, sweeps, residual = vel_free, 0, 0.0  # (replaced by the first round's)
    for _ in range(ROUNDS):
        nu, nfree, pinned = 0, 0, False
        for i in range(ne, n):
            lam[i] = lo[i] if at_lo[i] else hi[i] if at_hi[i] else 0.0
            pinned = pinned or at_lo[i] or at_hi[i]
            if kind[i] == KIND_GRIP:
                if not (at_lo[i] or at_hi[i]):
                    free_grip[nfree], nfree = i, nfree + 1
            elif not dormant[i]:
                its[nu], nu = i, nu + 1
        vel_p = vel_free.copy()
        if pinned:  # (none in most rounds: nothing to add)
            apply_rows(rw, at_lo | at_hi, resp_a, resp_b, lam, vel_p)
        ok, vel, sweeps, residual = _round(
            bw, tree, h, rw, n, lam, vel_p, its, nu, (free_grip, nfree, body), lam0,
            iterations, asleep,
        )  # fmt: skip
        if not ok:
            return False, lam, vel, 0, 0.0
        if not _update_sets(rw, ne, n, lam, vel, grip0, ngrip, dormant, at_lo, at_hi):
            return True, lam, vel, sweeps, residual
    for i in range(n):
        lam[i] = min(max(lam[i], lo[i]), hi[i])
    return True, lam, vel, sweeps, residual


@njit(cache=True, error_model="numpy")
def _update_sets(rw, ne, n, lam, vel, grip0, ngrip, dormant, at_lo, at_hi):
    """Wake crossed dormant rows (and their friction), pin and free grip rows; True when
    anything changed.

    The row arrays are taken out of the table once: an array read from a tuple inside an
    and/or costs two uncancelled reference counts each time (~300 ns, numba 0.68)."""
    lo, hi, comp, bias, fric = rw[4], rw[5], rw[6], rw[7], rw[8]
    changed = False
    for i in range(ne, n):
        r = row_velocity(rw, i, vel) + comp[i] * lam[i] + bias[i]
        if dormant[i] and fric[i] < 0 and r < 0.0:
            dormant[i], changed = False, True
        elif grip0 <= i < grip0 + ngrip:
            if (at_hi[i] and r > 0.0) or (at_lo[i] and r < 0.0):
                at_lo[i], at_hi[i], changed = False, False, True
            elif not (at_lo[i] or at_hi[i]) and (lam[i] < lo[i] or lam[i] > hi[i]):
                at_lo[i], at_hi[i], changed = lam[i] < lo[i], lam[i] > hi[i], True
    for i in range(ne, n):
        if fric[i] >= 0 and dormant[i] and not dormant[fric[i]]:
            dormant[i] = False
    return changed
