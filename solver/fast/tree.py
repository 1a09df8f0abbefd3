"""Exact solves of two-sided row tables: linear-time over the joint tree, and dense.

The rows solve  J v + C λ + β = 0  with  v = v_free + h M⁻¹ Jᵀ λ.  With the velocity
change y = v − v_free as an unknown beside λ this is the sparse symmetric system
(Baraff, "Linear-time dynamics using Lagrange multipliers", 1996)

    [ M/h   −Jᵀ ] [y]   [      0      ]
    [ −J    −C  ] [λ] = [ J v_free + β ],

quasi-definite (M/h ≻ 0; C ≻ 0 once every hard row is regularised), so it has a
signed block Cholesky factorisation in any symmetric order (the order still matters for
accuracy: see ``solver.fast.pack._forest``).  Its graph has one node per movable body
(6×6 block M_b/h, M_b = diag(m, m, m, R I Rᵀ)) and one per joint (its 3 anchor rows
and 3 rheology rows, block −diag(C)), plus one for the grip's rows: a forest, because
the bones form a tree and immovable bodies are left out.  Eliminating children before
parents,

    D_i = K_ii − Σ_c K_ic D_c⁻¹ K_ci,    z_i = r_i − Σ_c K_ic D_c⁻¹ z_c,
    x_root = D_root⁻¹ z_root,            x_i = D_i⁻¹ (z_i − K_ip x_p),

creates no fill, so the cost is O(nodes) 6×6 block operations.  D_i is positive
definite for bodies and negative definite for row nodes; each is factored as
D_i = ±L Lᵀ, and with Y = L⁻¹ K_ip the update is K_pi D_i⁻¹ K_ip = ±YᵀY.
``dense_solve`` (Cholesky of Q = h J M⁻¹ Jᵀ + C) is the simple alternative, kept for
tests and the benchmark.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, error_model="numpy")
def chol(a, m):
    """In-place lower Cholesky factor of a[:m, :m] (lower triangle read); False if not SPD."""
    for j in range(m):
        d = a[j, j]
        for k in range(j):
            d -= a[j, k] * a[j, k]
        if not d > 0.0:
            return False
        d = math.sqrt(d)
        a[j, j] = d
        for i in range(j + 1, m):
            s = a[i, j]
            for k in range(j):
                s -= a[i, k] * a[j, k]
            a[i, j] = s / d
    return True


@njit(cache=True, error_model="numpy")
def forward(lo, m, b):
    """b ← L⁻¹ b in place for the factor in lo[:m, :m]."""
    for i in range(m):
        s = b[i]
        for k in range(i):
            s -= lo[i, k] * b[k]
        b[i] = s / lo[i, i]


@njit(cache=True, error_model="numpy")
def backward(lo, m, b):
    """b ← L⁻ᵀ b in place."""
    for i in range(m - 1, -1, -1):
        s = b[i]
        for k in range(i + 1, m):
            s -= lo[k, i] * b[k]
        b[i] = s / lo[i, i]


@njit(cache=True, error_model="numpy")
def chol_solve(lo, m, b):
    """b ← (L Lᵀ)⁻¹ b in place."""
    forward(lo, m, b)
    backward(lo, m, b)


@njit(cache=True, error_model="numpy")
def _chol_block(dm, i, m, sign):
    """dm[i, :m, :m] ← lower Cholesky factor L of sign·dm[i] (lower triangle read), with
    the *reciprocal* 1/L_jj on the diagonal (the block solves multiply instead of
    divide), indexed in place (no array views: they cost reference counting here)."""
    for j in range(m):
        d = sign * dm[i, j, j]
        for k in range(j):
            d -= dm[i, j, k] * dm[i, j, k]
        if not d > 0.0:
            return False
        inv = 1.0 / math.sqrt(d)
        dm[i, j, j] = inv
        for r in range(j + 1, m):
            s = sign * dm[i, r, j]
            for k in range(j):
                s -= dm[i, r, k] * dm[i, j, k]
            dm[i, r, j] = s * inv
    return True


@njit(cache=True, error_model="numpy")
def _chol6(dm, i, sign):
    """_chol_block of a 6×6 block (constant trip counts: the compiler unrolls them)."""
    for j in range(6):
        d = sign * dm[i, j, j]
        for k in range(j):
            d -= dm[i, j, k] * dm[i, j, k]
        if not d > 0.0:
            return False
        inv = 1.0 / math.sqrt(d)
        dm[i, j, j] = inv
        for r in range(j + 1, 6):
            s = sign * dm[i, r, j]
            for k in range(j):
                s -= dm[i, r, k] * dm[i, j, k]
            dm[i, r, j] = s * inv
    return True


@njit(cache=True, error_model="numpy")
def _forward_block(dm, i, m, x):
    """x[i, :m] ← L_i⁻¹ x[i, :m] (reciprocal diagonal: _chol_block)."""
    if m == 6:
        for r in range(6):
            s = x[i, r]
            for k in range(r):
                s -= dm[i, r, k] * x[i, k]
            x[i, r] = s * dm[i, r, r]
        return
    for r in range(m):
        s = x[i, r]
        for k in range(r):
            s -= dm[i, r, k] * x[i, k]
        x[i, r] = s * dm[i, r, r]


@njit(cache=True, error_model="numpy")
def _backward_block(dm, i, m, x):
    """x[i, :m] ← L_i⁻ᵀ x[i, :m] (reciprocal diagonal: _chol_block)."""
    if m == 6:
        for r in range(5, -1, -1):
            s = x[i, r]
            for k in range(r + 1, 6):
                s -= dm[i, k, r] * x[i, k]
            x[i, r] = s * dm[i, r, r]
        return
    for r in range(m - 1, -1, -1):
        s = x[i, r]
        for k in range(r + 1, m):
            s -= dm[i, k, r] * x[i, k]
        x[i, r] = s * dm[i, r, r]


@njit(cache=True, error_model="numpy")
def row_velocity(rw, r, vel):
    """J_r v (static sides skipped)."""
    a, b = rw[0][r], rw[1][r]
    w = 0.0
    if a >= 0:
        for k in range(6):
            w += rw[2][r, k] * vel[a, k]
    if b >= 0:
        for k in range(6):
            w += rw[3][r, k] * vel[b, k]
    return w


@njit(cache=True, error_model="numpy")
def node_rows(i, nb, rheo_start, out):
    """Rows of joint node i = nb + j into out (3 anchor rows 3j..3j+2, then the rheology
    rows rheo_start[j]..+2 when rheo_start[j] ≥ 0); returns their count (0 for a body)."""
    if i < nb:
        return 0
    j = i - nb
    for k in range(3):
        out[k] = 3 * j + k
    if rheo_start[j] < 0:
        return 3
    for k in range(3):
        out[3 + k] = rheo_start[j] + k
    return 6


@njit(cache=True, error_model="numpy")
def init_nodes(seq, nseq, nb, rw, vel_free, h, mass, inertia_w, rows, size, dm, z):
    """D_i and right-hand sides z_i before elimination."""
    for q in range(nseq):
        i = seq[q]
        for r in range(6):
            for c in range(6):
                dm[i, r, c] = 0.0
        if i < nb:
            size[i] = 6
            for k in range(3):
                dm[i, k, k] = mass[i] / h
                for c in range(3):
                    dm[i, 3 + k, 3 + c] = inertia_w[i, k, c] / h
            continue
        for k in range(size[i]):
            dm[i, k, k] = -rw[6][rows[i, k]]
    init_rhs(seq, nseq, nb, rw, vel_free, rows, size, z)


@njit(cache=True, error_model="numpy")
def init_rhs(seq, nseq, nb, rw, vel_free, rows, size, z):
    """z_i: 0 for bodies, J v_free + β for row nodes."""
    for q in range(nseq):
        i = seq[q]
        for k in range(6):
            z[i, k] = 0.0
        if i >= nb:
            for k in range(size[i]):
                r = rows[i, k]
                z[i, k] = row_velocity(rw, r, vel_free) + rw[7][r]


@njit(cache=True, error_model="numpy")
def _coupling(i, p, nb, rw, rows, size, g):
    """g = K_ip = −J block between body node and row node (transposed when i is the body)."""
    body_is_p = i >= nb
    row_node = i if body_is_p else p
    body, body_a, jac_a, jac_b = p if body_is_p else i, rw[0], rw[2], rw[3]
    for k in range(size[row_node]):
        r = rows[row_node, k]
        on_a = body_a[r] == body
        for c in range(6):
            v = -jac_a[r, c] if on_a else -jac_b[r, c]
            if body_is_p:
                g[k, c] = v
            else:
                g[c, k] = v


@njit(cache=True, error_model="numpy")
def _eliminate6(i, p, sign, dm, y, g):
    """_eliminate for 6×6 blocks (bodies and joints with rheology: most of a doll's
    nodes), with constant trip counts the compiler unrolls."""
    for c in range(6):
        for r in range(6):
            s = g[r, c]
            for k in range(r):
                s -= dm[i, r, k] * y[i, k, c]
            y[i, r, c] = s * dm[i, r, r]
    for a in range(6):
        for b in range(a + 1):
            s = 0.0
            for k in range(6):
                s += y[i, k, a] * y[i, k, b]
            dm[p, a, b] -= sign * s


@njit(cache=True, error_model="numpy")
def _eliminate(i, p, m, mp, sign, dm, y, g):
    """With D_i = sign·L Lᵀ: Y = L⁻¹ G, D_p −= sign·YᵀY (lower triangles only: that is
    what the factorisation reads; L's diagonal holds its reciprocal)."""
    if m == 6 and mp == 6:
        _eliminate6(i, p, sign, dm, y, g)
        return
    for c in range(mp):
        for r in range(m):
            s = g[r, c]
            for k in range(r):
                s -= dm[i, r, k] * y[i, k, c]
            y[i, r, c] = s * dm[i, r, r]
    for a in range(mp):
        for b in range(a + 1):
            s = 0.0
            for k in range(m):
                s += y[i, k, a] * y[i, k, b]
            dm[p, a, b] -= sign * s


@njit(cache=True, error_model="numpy")
def tree_factor(seq, nseq, parent, nb, rw, rows, size, tw):
    """Factor the forest's system in place, children first (module docstring): each
    D_i = ±L Lᵀ, Y_i = L⁻¹ K_ip, D_p −= ±Y_iᵀY_i.  False when a block is not definite
    (degenerate rows: the caller falls back)."""
    dm, y, g = tw[0], tw[1], tw[3]
    for q in range(nseq):
        i = seq[q]
        m = size[i]
        sign = 1.0 if i < nb else -1.0
        if not (_chol6(dm, i, sign) if m == 6 else _chol_block(dm, i, m, sign)):
            return False
        p = parent[i]
        if p >= 0:
            _coupling(i, p, nb, rw, rows, size, g)
            _eliminate(i, p, m, size[p], sign, dm, y, g)
    return True


@njit(cache=True, error_model="numpy")
def _fold_up(i, p, m, mp, sign, y, x):
    """x_p −= sign·Y_iᵀ x_i (6×6 blocks with constant trip counts)."""
    if m == 6 and mp == 6:
        for a in range(6):
            s = 0.0
            for k in range(6):
                s += y[i, k, a] * x[i, k]
            x[p, a] -= sign * s
        return
    for a in range(mp):
        s = 0.0
        for k in range(m):
            s += y[i, k, a] * x[i, k]
        x[p, a] -= sign * s


@njit(cache=True, error_model="numpy")
def _take_down(i, p, m, mp, y, x):
    """x_i −= Y_i x_p."""
    if m == 6 and mp == 6:
        for k in range(6):
            s = 0.0
            for c in range(6):
                s += y[i, k, c] * x[p, c]
            x[i, k] -= s
        return
    for k in range(m):
        for c in range(mp):
            x[i, k] -= y[i, k, c] * x[p, c]


@njit(cache=True, error_model="numpy")
def tree_substitute(seq, nseq, parent, nb, size, tw, x, fwd, fwd_tag, bwd, bwd_tag):
    """x ← K⁻¹ x with the factors of ``tree_factor``; x (nodes, 6): right-hand sides in,
    solution out (body nodes: velocity change y; row nodes: λ).

    Only nodes with fwd[i] == fwd_tag take part in the forward pass and only nodes with
    bwd[i] == bwd_tag are solved for (zero arrays and tags solve everything): a node
    whose subtree has no right-hand side has nothing to pass up, and a node is solved
    from its parent alone, so a sparse right-hand side needs the forward pass only on
    the paths from its nodes to their roots, and the solution at some nodes only the
    backward pass on the paths from the roots down to them (both sets root-closed)."""
    dm, y = tw[0], tw[1]
    for q in range(nseq):  # L⁻¹ z_i, children first, folded into the parent
        i = seq[q]
        if fwd[i] != fwd_tag:
            continue
        m = size[i]
        _forward_block(dm, i, m, x)
        p = parent[i]
        if p >= 0:
            _fold_up(i, p, m, size[p], 1.0 if i < nb else -1.0, y, x)
    for q in range(nseq - 1, -1, -1):  # x_i = sign·L⁻ᵀ(L⁻¹ z_i − Y x_p), parents first
        i = seq[q]
        if bwd[i] != bwd_tag:
            continue
        p = parent[i]
        m = size[i]
        if p >= 0:
            _take_down(i, p, m, size[p], y, x)
        _backward_block(dm, i, m, x)
        sign = 1.0 if i < nb else -1.0
        for k in range(m):
            x[i, k] *= sign


@njit(cache=True, error_model="numpy")
def forest_sequence(tree, nb, movable, free_grip, ngrip, body, asleep, joint_bone):
    """Fill the elimination sequence (seq, parent, rows, size of ``tree``) for the joint
    forest and, with ngrip > 0, the grip's node of the rows free_grip[:ngrip], a leaf of
    the gripped body (its own root when the body cannot move); returns its length.
    Sleeping islands (asleep (nb,) bool) are left out: each is a whole component of the
    forest, with no rows (solver.sleep)."""
    order, parent, rheo_start, _, seq, rows, size, _ = tree
    node = nb + len(rheo_start)
    nseq = 0
    if ngrip:
        seq[0], nseq = node, 1
        parent[node] = body if movable[body] > 0.0 else -1
        size[node] = ngrip
        for k in range(ngrip):
            rows[node, k] = free_grip[k]
    for i in order:
        if asleep[i] if i < nb else asleep[joint_bone[i - nb]]:
            continue
        seq[nseq] = i
        nseq += 1
        size[i] = node_rows(i, nb, rheo_start, rows[i])
    return nseq


@njit(cache=True, error_model="numpy")
def tree_solve(seq, nseq, parent, nb, rw, vel_free, h, mass, inertia_w, rows, size, tw, lam):
    """λ of the two-sided rows by block elimination over the forest (module docstring).

    seq[:nseq]: nodes, children before parents; parent: node → parent node or −1;
    rows/size: each row node's rows; tw = (D, Y, w, g) workspaces.  False when a
    block is not definite (degenerate rows: the caller falls back)."""
    w = tw[2]
    init_nodes(seq, nseq, nb, rw, vel_free, h, mass, inertia_w, rows, size, tw[0], w)
    if not tree_factor(seq, nseq, parent, nb, rw, rows, size, tw):
        return False
    every = np.zeros(len(parent), np.int64)
    tree_substitute(seq, nseq, parent, nb, size, tw, w, every, 0, every, 0)
    for q in range(nseq):
        i = seq[q]
        if i >= nb:
            for k in range(size[i]):
                lam[rows[i, k]] = w[i, k]
    return True


@njit(cache=True, error_model="numpy")
def _dot6(x, i, y, j):
    s = 0.0
    for k in range(6):
        s += x[i, k] * y[j, k]
    return s


@njit(cache=True, error_model="numpy")
def dense_solve(rw, resp_a, resp_b, n, vel_free, lam):
    """λ = −Q⁻¹(J v_free + β), Q = A + diag(C), A_ij = jac_i·resp_j over shared bodies."""
    q = np.zeros((n, n))
    a, b, ja, jb = rw[0], rw[1], rw[2], rw[3]
    for i in range(n):
        for j in range(i + 1):
            s = 0.0
            if a[i] >= 0 and a[i] == a[j]:
                s += _dot6(ja, i, resp_a, j)
            if a[i] >= 0 and a[i] == b[j]:
                s += _dot6(ja, i, resp_b, j)
            if b[i] >= 0 and b[i] == a[j]:
                s += _dot6(jb, i, resp_a, j)
            if b[i] >= 0 and b[i] == b[j]:
                s += _dot6(jb, i, resp_b, j)
            q[i, j] = s
        q[i, i] += rw[6][i]
        lam[i] = -(row_velocity(rw, i, vel_free) + rw[7][i])
    if not chol(q, n):
        return False
    chol_solve(q, n, lam)
    return True
