"""Compiled hybrid solve (solver.solve.hybrid): joints, grip and sticking leaf contacts exact
by the tree, the other active bounded rows by PGS on their Schur complement, dormant rows
checked afterwards.

The joints' rows are the first ``ne`` rows of the table; grip rows are rows grip0 … grip0 +
ngrip − 1 (a node of the forest while inside their bounds, pinned at a bound otherwise, as
in the direct solve); a leaf contact (``leaf_contacts``: a bone against the static world)
is a node of its normal row and its two friction rows (the normal row alone without
friction), hung from its bone while it pushes and sticks (the static side adds no edge, so
the forest stays a forest); once its friction leaves the pyramid, or it would pull while
held in the tangent plane, it slides: iterated with the U rows for the rest of the step
(one with friction that touched down or slid the step before starts there:
solver.solve.hybrid.iterated_first); a frictionless one that would pull is pinned at λ = 0.
Every other row is iterated (U) or dormant (solver.hybrid.dormant_rows). With the forest
factored once per round (tree_factor), each U row r costs one substitution: the body
right-hand side J_rᵀ gives every body's velocity change per unit λ_r with the joints and
grip holding, so S[:, r] = J_U y⁽ʳ⁾ + C_r e_r; it runs forward only on the root paths of
r's bodies and backward only on those of the U rows' bodies. The base substitution (U
forces zero) gives s = J_U (v_free + y⁽⁰⁾) + β_U. After PGS on S
(solver.solve.pgs.dense_pgs), one more substitution with the U forces folded into v_free
gives λ of the exact rows and the velocities. Without U rows one substitution does it all.
"""

from __future__ import annotations

import inspect

import numpy as np

from solver.compiled.flat import square
from solver.jit import kernel
from solver.rows.table import KIND_CONTACT, KIND_GRIP
from solver.solve import hybrid
from solver.solve.direct_kernel import (
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
from solver.solve.pgs import dense_pgs_into
from solver.solve.response_kernel import apply_listed, copy6

ROUNDS = inspect.signature(hybrid.hybrid_solve).parameters["rounds"].default
SLID = hybrid.SLID
NU_CAP = 64  # iterated rows whose Schur complement fits the step's scratch (kernel.step_arrays)


@kernel(error_model="numpy")
def _body_dot(rw, r, x, movable):
    """J_r · x over the movable sides of row r (x (nodes, 6), body nodes first)."""
    a, b = rw.body_a[r], rw.body_b[r]
    s = 0.0
    if a >= 0 and movable[a] > 0.0:
        for k in range(6):
            s += rw.jac_a[r, k] * x[a, k]
    if b >= 0 and movable[b] > 0.0:
        for k in range(6):
            s += rw.jac_b[r, k] * x[b, k]
    return s


@kernel(error_model="numpy")
def _mark_path(body, parent, movable, mark, tag):
    """mark[node] = tag on the path from a movable body to its root."""
    if body < 0 or movable[body] <= 0.0:
        return
    node = body
    while node >= 0 and mark[node] != tag:
        mark[node] = tag
        node = parent[node]


@kernel(error_model="numpy", _nrt=False)
def _schur(rw, its, nu, seq, nseq, parent, nb, size, tw, movable, x, path, needed, s_mat):
    """S (nu, nu) into s_mat over the rows its[:nu], column by column (module docstring);
    path, needed: (nodes,) int scratch."""
    path[:] = 0
    needed[:] = 0
    for i in range(nu):
        _mark_path(rw.body_a[its[i]], parent, movable, needed, 1)
        _mark_path(rw.body_b[its[i]], parent, movable, needed, 1)
    for k in range(nu):
        r = its[k]
        _mark_path(rw.body_a[r], parent, movable, path, k + 1)
        _mark_path(rw.body_b[r], parent, movable, path, k + 1)
        for q in range(nseq):
            i = seq[q]
            if path[i] == k + 1 or needed[i] == 1:
                for c in range(6):
                    x[i, c] = 0.0
        a, b = rw.body_a[r], rw.body_b[r]
        if a >= 0 and movable[a] > 0.0:
            for c in range(6):
                x[a, c] += rw.jac_a[r, c]
        if b >= 0 and movable[b] > 0.0:
            for c in range(6):
                x[b, c] += rw.jac_b[r, c]
        tree_substitute(seq, nseq, parent, nb, size, tw, x, path, k + 1, needed, 1)
        for i in range(nu):
            s_mat[i, k] = _body_dot(rw, its[i], x, movable)
        s_mat[k, k] += rw.comp[r]
    for i in range(nu):
        for k in range(i):
            s_mat[i, k] = s_mat[k, i] = 0.5 * (s_mat[i, k] + s_mat[k, i])


@kernel(error_model="numpy", _nrt=False)
def _solve_exact(seq, nseq, parent, nb, movable, rows, size, tw, vel, lam, out, forward):
    """λ of the forest's rows and out = vel + y, with v_free replaced by ``vel``, from
    the right-hand sides of ``vel`` in tw.rhs (init_rhs made them; forward False: init_nodes
    made them and tree_factor has run the forward pass)."""
    x = tw.rhs
    if forward:
        forward_pass(seq, nseq, parent, nb, size, tw, x, parent, ALL)
    backward_pass(seq, nseq, parent, nb, size, tw, x, parent, ALL)
    copy6(vel, out)
    for q in range(nseq):
        i = seq[q]
        if i < nb:
            if movable[i] > 0.0:
                for k in range(6):
                    out[i, k] += x[i, k]
        else:
            for k in range(size[i]):
                lam[rows[i, k]] = x[i, k]


@kernel(error_model="numpy", _nrt=False)
def dormant_rows(rw, n, lam0, out):
    """out[:n] ← solver.solve.hybrid.dormant_rows on the table's first n rows."""
    lo, hi, bias, fric = rw.lo, rw.hi, rw.bias, rw.fric_of  # (not rw.x in and/or: _update_sets)
    for i in range(n):
        out[i] = False
        if lo[i] == 0.0 and hi[i] == np.inf and fric[i] < 0:
            out[i] = lam0[i] == 0.0 and bias[i] > 0.0
    for i in range(n):
        if fric[i] >= 0:
            out[i] = out[fric[i]]


@kernel(error_model="numpy", _nrt=False)
def _iterate(rw, its, nu, lam0, local, lo, hi, fric, mu, start):
    """PGS on S's rows: bounds, friction (indices local to its) and warm start into
    lo … start [:nu]; local (≥ rows) int scratch, read only where its[:nu] wrote it."""
    for i in range(nu):
        local[its[i]] = i
    for i in range(nu):
        r = its[i]
        lo[i], hi[i], mu[i], start[i], fric[i] = rw.lo[r], rw.hi[r], rw.mu[r], lam0[r], -1
        normal = rw.fric_of[r]
        if normal >= 0 and 0 <= local[normal] < nu and its[local[normal]] == normal:
            fric[i] = local[normal]


@kernel(error_model="numpy", _nrt=False)
def _iterated(rw, its, nu, seq, nseq, parent, nb, size, tw, movable, lam0, iters, sv, s_mat):
    """λ_U of the rows its[:nu] into sv's lam_u by PGS on their Schur complement (built in
    s_mat (nu, nu)), the base velocities' s_U in sv's s_vec; (sweeps, residual)."""
    ints, (s_vec, lo, hi, mu, start, lam_u, r_u) = sv.ints, sv.values
    _schur(
        rw, its, nu, seq, nseq, parent, nb, size, tw, movable, tw.rhs, ints.path, ints.needed, s_mat
    )
    _iterate(rw, its, nu, lam0, ints.local, lo, hi, ints.fric, mu, start)
    return dense_pgs_into(nu, s_mat, s_vec, lo, hi, ints.fric, mu, start, iters, 1e-12, lam_u, r_u)


@kernel(error_model="numpy", _nrt=True)
def _iterated_large(rw, its, nu, seq, nseq, parent, nb, size, tw, movable, lam0, iters, sv):
    """``_iterated`` with S in a matrix made for it, for more than NU_CAP rows."""
    s_mat = np.empty((nu, nu))
    return _iterated(rw, its, nu, seq, nseq, parent, nb, size, tw, movable, lam0, iters, sv, s_mat)


@kernel(error_model="numpy", inline="always")
def _round(bw, tree, h, rw, lam, vel_p, its, nu, nodes, lam0, iters, asleep, sv, vel):
    """One solve with the current sets into lam and vel: (ok, sweeps, residual).
    bw: the solvers' model arrays (solver.solve.dispatch_kernel.solve); nodes = (free grip rows,
    their count, the gripped body, the sticking leaf contacts' normal rows, their count,
    each normal row's first friction row); sv: the solvers' scratch (kernel.step_arrays)."""
    _, parent, _, _, _, seq, rows, size, tw = tree
    joint_bone, mass, movable, resp_a, resp_b, _, inertia_w = bw
    nb = len(vel_p)
    free_grip, ngrip, body, leaves, nleaf, first_friction = nodes
    leaf_nodes = (rw, leaves, nleaf, first_friction)
    nseq = forest_sequence(
        tree, nb, movable, free_grip, ngrip, body, leaf_nodes, (asleep, sv.alone), joint_bone
    )
    init_nodes(seq, nseq, nb, rw, vel_p, h, mass, inertia_w, rows, size, tw.block, tw.rhs)
    if not tree_factor(seq, nseq, parent, nb, rw, rows, size, tw):
        return False, 0, 0.0
    _solve_exact(seq, nseq, parent, nb, movable, rows, size, tw, vel_p, lam, vel, False)
    if nu == 0:
        return True, 0, 0.0
    s_vec, lam_u, pushed = sv.values.s_vec, sv.values.lam_u, sv.pushed
    for i in range(nu):
        s_vec[i] = row_velocity(rw, its[i], vel) + rw.bias[its[i]]
    if nu <= NU_CAP:
        sweeps, residual = _iterated(rw, its, nu, seq, nseq, parent, nb, size, tw, movable,
                                     lam0, iters, sv, square(sv.s_mat, nu))  # fmt: skip
    else:
        sweeps, residual = _iterated_large(
            rw, its, nu, seq, nseq, parent, nb, size, tw, movable, lam0, iters, sv
        )
    for i in range(nu):
        lam[its[i]] = lam_u[i]
    copy6(vel_p, pushed)
    apply_listed(rw, its, nu, resp_a, resp_b, lam, pushed)
    init_rhs(seq, nseq, nb, rw, pushed, rows, size, tw.rhs)
    _solve_exact(seq, nseq, parent, nb, movable, rows, size, tw, pushed, lam, vel, True)
    return True, sweeps, residual


@kernel(error_model="numpy", inline="always")
def hybrid_solve(bw, tree, h, rw, n, ne, vel_free, lam0, iterations, grip, skips, asleep, sv,
                 lam, vel, rounds):  # fmt: skip
    """(code, sweeps, residual) as solver.solve.hybrid.hybrid_solve, λ into lam[:n] and the
    velocities into vel; code 0: the sets settled, 1: not within ``rounds`` (λ clipped to
    its bounds), 2: the exact system is degenerate. bw: the solvers' model arrays
    (solver.solve.dispatch_kernel.solve); h: the step; skips = (leave dormant rows out of
    the iteration, solve leaf contacts in the forest: Options.dormant_rows, leaf_contacts);
    asleep (nb,) bool: sleeping bodies (their islands are not in the forest, but for the
    bodies rows act on: ``sleeping_sides``); sv: the
    solvers' scratch (kernel.step_arrays: nothing is allocated unless more than NU_CAP rows
    are iterated). Without iterated rows (a table of joint and grip rows only) this is the
    direct solve's active set on the grip (kernel.direct)."""
    grip0, ngrip, body = grip
    resp_a, resp_b = bw.resp_a, bw.resp_b
    at_lo, at_hi, dormant, leaf, sliding = sv.flags
    its, pinned, _, _, _, _, free_grip, leaves, first_friction = sv.ints
    vel_p = sv.vel_p
    skip, leaves_on = skips
    if skip:
        dormant_rows(rw, n, lam0, dormant)
    for i in range(n):
        at_lo[i], at_hi[i], sliding[i], lam[i] = False, False, False, 0.0
        if not skip:
            dormant[i] = False
    leaf_contacts(rw, ne, n, bw.inv_mass, asleep, leaves_on, leaf, first_friction)
    sleeping_sides(rw, ne, n, asleep, sv.alone)
    lo, hi, kind, fric = rw.lo, rw.hi, rw.kind, rw.fric_of
    for i in range(ne, n):  # solver.solve.hybrid.iterated_first
        c = fric[i]
        if c >= 0 and abs(lam0[i]) >= SLID * rw.mu[i] * lam0[c]:
            sliding[c] = True
    sweeps, residual = 0, 0.0
    for _ in range(rounds):
        nu, nfree, nleaf, npin = 0, 0, 0, 0
        for i in range(ne, n):
            lam[i] = lo[i] if at_lo[i] else hi[i] if at_hi[i] else 0.0
            held = at_lo[i] or at_hi[i]
            if held:
                pinned[npin], npin = i, npin + 1
            if kind[i] == KIND_GRIP:
                if not held:
                    free_grip[nfree], nfree = i, nfree + 1
            elif leaf[i]:  # a node while it sticks, iterated once it slides
                c = i if fric[i] < 0 else fric[i]
                if not (at_lo[c] or dormant[i]):
                    if sliding[c]:
                        its[nu], nu = i, nu + 1
                    elif c == i:
                        leaves[nleaf], nleaf = i, nleaf + 1
            elif not dormant[i]:
                its[nu], nu = i, nu + 1
        copy6(vel_free, vel_p)
        apply_listed(rw, pinned, npin, resp_a, resp_b, lam, vel_p)  # (most rounds: none)
        nodes = (free_grip, nfree, body, leaves, nleaf, first_friction)
        ok, sweeps, residual = _round(
            bw, tree, h, rw, lam, vel_p, its, nu, nodes, lam0, iterations, asleep, sv, vel
        )
        if not ok:
            return 2, 0, 0.0
        sets = (leaf, first_friction, sliding)
        if not _update_sets(rw, ne, n, lam, vel, (grip0, ngrip), sets, dormant, at_lo, at_hi):
            return 0, sweeps, residual
    for i in range(n):
        lam[i] = min(max(lam[i], lo[i]), hi[i])
    return 1, sweeps, residual


@kernel(error_model="numpy", inline="always")
def leaf_contacts(rw, ne, n, movable, asleep, on, leaf, first_friction):
    """leaf[ne:n] ← solver.solve.hybrid.leaf_contacts, and the bone on the other side awake and
    movable (the forest hangs the contact from it); first_friction[c] ← the first of normal
    row c's two friction rows (contact_rows makes them in pairs), −1 without. (Inlined:
    called, it cost 0.75 µs a step on every scene through the direct solve.)"""
    fric = rw.fric_of
    for i in range(ne, n):
        a, b = rw.body_a[i], rw.body_b[i]
        bone = a if b < 0 else b if a < 0 else -1
        leaf[i] = (
            on and rw.kind[i] == KIND_CONTACT and rw.comp[i] > 0.0 and bone >= 0
            and movable[bone] > 0.0 and not asleep[bone]
        )  # fmt: skip
        first_friction[i] = -1
    for i in range(ne, n):
        if fric[i] >= 0:
            leaf[fric[i]] = leaf[fric[i]] and rw.comp[i] > 0.0
            if first_friction[fric[i]] < 0:
                first_friction[fric[i]] = i
    for i in range(ne, n):
        if fric[i] >= 0:
            leaf[i] = leaf[fric[i]]


@kernel(error_model="numpy", inline="always")
def sleeping_sides(rw, ne, n, asleep, alone):
    """alone[b] ← body b sleeps and one of rows ne … n − 1 acts on it: an awake body resting
    on a sleeping one that it did not wake (solver.advance.sleep).  The forest takes such a
    body as a free root of its own (direct_kernel.forest_sequence), as the numpy step keeps
    it in its system; its pose stays as it was (the step keeps sleeping bodies')."""
    a, b = rw.body_a, rw.body_b
    for k in range(len(alone)):
        alone[k] = False
    for i in range(ne, n):
        if a[i] >= 0 and asleep[a[i]]:
            alone[a[i]] = True
        if b[i] >= 0 and asleep[b[i]]:
            alone[b[i]] = True


@kernel(error_model="numpy")
def _update_sets(rw, ne, n, lam, vel, grip, leaves, dormant, at_lo, at_hi):
    """Wake crossed dormant rows (and their friction), pin and free grip rows and leaf
    contacts (by their normal rows), slide a sticking leaf contact whose friction leaves
    its pyramid or that would pull; True when anything changed.  grip = (first row,
    count); leaves = (leaf, first_friction, sliding) (``hybrid_solve``).

    The row arrays are taken out of the table once: an array read from a tuple inside an
    and/or costs two uncancelled reference counts each time (~300 ns, numba 0.68)."""
    lo, hi, comp, bias, fric, mu = rw.lo, rw.hi, rw.comp, rw.bias, rw.fric_of, rw.mu
    (grip0, ngrip), (leaf, first_friction, sliding) = grip, leaves
    changed = False
    for i in range(ne, n):
        r = row_velocity(rw, i, vel) + comp[i] * lam[i] + bias[i]
        held = at_lo[i] or at_hi[i]
        if dormant[i] and fric[i] < 0 and r < 0.0:
            dormant[i], changed = False, True
        elif grip0 <= i < grip0 + ngrip or (leaf[i] and fric[i] < 0 and not sliding[i]):
            if (at_hi[i] and r > 0.0) or (at_lo[i] and r < 0.0):
                at_lo[i], at_hi[i], changed = False, False, True
            elif not held and (lam[i] < lo[i] or lam[i] > hi[i]) and first_friction[i] < 0:
                at_lo[i], at_hi[i], changed = lam[i] < lo[i], lam[i] > hi[i], True
            elif not held and lam[i] < lo[i]:  # held in the tangent, it would pull
                sliding[i], changed = True, True
            elif not (held or dormant[i]) and first_friction[i] >= 0:
                f = first_friction[i]
                if abs(lam[f]) > mu[f] * lam[i] or abs(lam[f + 1]) > mu[f + 1] * lam[i]:
                    sliding[i], changed = True, True
    for i in range(ne, n):
        if fric[i] >= 0 and dormant[i] and not dormant[fric[i]]:
            dormant[i] = False
    return changed
