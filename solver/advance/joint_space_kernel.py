"""Compiled joint-space BDF2 step (solver.advance.joint_space's twin): the same step,
solved by the articulated-body recursion in O(n) instead of a dense solve.

All of a stepper's arrays are views of two flat buffers (``views``: the one definition of
their layout), so a step crosses into compiled code with four arguments; ``advance``
takes a whole step (its parts) and checks the result.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import carray

from solver.compiled.flat import row_pointer
from solver.jit import kernel
from solver.kin_kernel import (
    add,
    cross,
    qconj,
    qexp,
    qlog,
    qmul,
    qnormalize,
    qrotate,
    quat_at,
    scale,
    vec,
    vec_from,
)


class Tree(NamedTuple):
    """The tree's joints, parents first: child (n,) and parent (n,) body (the world: the
    last body), joint (n,) the model's joint index.  int64."""

    child: np.ndarray
    parent: np.ndarray
    joint: np.ndarray


class Params(NamedTuple):
    """The model, per tree joint (n, ·) or body (nb1, ·): anchor_parent, anchor_child (n,3)
    m in each body's frame; kf (n,3) N·m/rad, df (n,3) N·m·s/rad (0 for a free joint);
    mass (nb1,) kg; inertia (nb1,3,3) kg·m² body frame; options (8,): OPT_* below."""

    anchor_parent: np.ndarray
    anchor_child: np.ndarray
    kf: np.ndarray
    df: np.ndarray
    mass: np.ndarray
    inertia: np.ndarray
    options: np.ndarray


class Arrays(NamedTuple):
    """The state (world axes, per body (nb1, ·) with the world last): quat (w,x,y,z) and
    quat_prev (the last part's start); omega rad/s; momentum and momentum_prev (6,): L about
    the centre of mass, N·m·s, then p, N·s; pos m from the step's origin (OPT_ORIGIN: the
    tree's first fixed anchor; the step's spatial quantities are about it, and about the
    world origin they would lose digits on bodies far from it); vel m/s (p/m); rest (n,4):
    each tree joint's elastic rest (parent frame); deflection (nj,3) rad and torque (nj,3)
    N·m per model joint; clock (4,): CLOCK_* below; world_pos m: pos from the world's
    origin; loads (nb1,6): the step's input, a torque about the centre (N·m) and a force
    at it (N) on each body."""

    quat: np.ndarray
    quat_prev: np.ndarray
    omega: np.ndarray
    momentum: np.ndarray
    momentum_prev: np.ndarray
    pos: np.ndarray
    vel: np.ndarray
    rest: np.ndarray
    deflection: np.ndarray
    torque: np.ndarray
    clock: np.ndarray
    world_pos: np.ndarray
    loads: np.ndarray


class Work(NamedTuple):
    """A part's workspace: quat_hat q̂ and quat_pred q̃ (nb1,4); motion S (n,6,3); inertia Φ
    and articulated I^A (nb1,6,6) about the step's origin; bias p^A, velocity V, residual f
    (nb1,6); pivot_inv D⁻¹ (n,3,3), coupling U = I^A S (n,6,3), rhs (n,3); rates (n,9): u*,
    θ*, u."""

    quat_hat: np.ndarray
    quat_pred: np.ndarray
    motion: np.ndarray
    inertia: np.ndarray
    articulated: np.ndarray
    bias: np.ndarray
    velocity: np.ndarray
    residual: np.ndarray
    pivot_inv: np.ndarray
    coupling: np.ndarray
    rhs: np.ndarray
    rates: np.ndarray


WIDTHS = (3, 3, 3, 3, 1, 9, 8, 4, 4, 3, 6, 6, 3, 3, 4, 3, 3, 4, 4, 4, 18, 36, 36, 6, 6, 6, 9, 18,
          3, 9, 3, 6)  # fmt: skip
ROWS = "nnnnbbobbbbbbbnjjobbnbbbbbnnnnbb"
"""Each float field's width and what counts its rows (n joints of the tree, b bodies and
the world, j joints of the model, o one), in ``views``' order."""
OPT_GRAVITY, OPT_MAX_SPEED, OPT_MAX_SPIN, OPT_ORIGIN = 0, 3, 4, 5
CLOCK_HPREV, CLOCK_GRIP_FORCE = 0, 1
GRIP_BODY, GRIP_ANCHOR, GRIP_TARGET, GRIP_RATE, GRIP_K, GRIP_D, GRIP_SIZE = 0, 1, 4, 7, 10, 11, 12
"""The grip vector: the body (-1: none), its point in the body frame, the target point at
the step's end and its velocity (world), the spring's stiffness and damping."""
OK, BROKEN = 0, 1


def offsets(n: int, nb1: int, nj: int) -> list[int]:
    """The float buffer's field offsets (len(WIDTHS) + 1) for n tree joints, nb1 bodies
    (the world included) and nj model joints (Python: made once per stepper)."""
    count = {"n": n, "b": nb1, "j": nj, "o": 1}
    out = [0]
    for rows, width in zip(ROWS, WIDTHS, strict=True):
        out.append(out[-1] + count[rows] * width)
    return out


@kernel(error_model="numpy", inline="always")
def _field(fb, off, i, rows, width):
    """Float field i as (rows, width), a view holding no reference to fb (as
    solver.compiled.flat's: the caller keeps fb alive)."""
    return carray(row_pointer(fb, off[i]), (rows, width))


@kernel(error_model="numpy", inline="always")
def _blocks(fb, off, i, rows, a):
    """Float field i as (rows, a, width/a) matrices (a view, as ``_field``)."""
    return carray(row_pointer(fb, off[i]), (rows, a, WIDTHS[i] // a))


@kernel(error_model="numpy", inline="always")
def views(fb, ib):
    """The named views of the buffers: (tree, model, state, work) tuples.  ib: n, nb1, nj,
    the float offsets, then child, parent and joint of each tree joint (parents first).
    Inlined: its views hold no reference to the buffers (``python_views`` makes the ones
    Python keeps)."""
    n, nb1, nj = ib[0], ib[1], ib[2]
    off = ib[3 : 4 + len(WIDTHS)]
    o = 4 + len(WIDTHS)
    tree = Tree(ib[o : o + n], ib[o + n : o + 2 * n], ib[o + 2 * n : o + 3 * n])
    model = Params(_field(fb, off, 0, n, 3), _field(fb, off, 1, n, 3), _field(fb, off, 2, n, 3),
             _field(fb, off, 3, n, 3), _field(fb, off, 4, nb1, 1)[:, 0],
             _blocks(fb, off, 5, nb1, 3), _field(fb, off, 6, 1, 8)[0, :])  # fmt: skip
    state = Arrays(_field(fb, off, 7, nb1, 4), _field(fb, off, 8, nb1, 4),
             _field(fb, off, 9, nb1, 3),
             _field(fb, off, 10, nb1, 6), _field(fb, off, 11, nb1, 6),
             _field(fb, off, 12, nb1, 3), _field(fb, off, 13, nb1, 3), _field(fb, off, 14, n, 4),
             _field(fb, off, 15, nj, 3), _field(fb, off, 16, nj, 3),
             _field(fb, off, 17, 1, 4)[0, :], _field(fb, off, 30, nb1, 3),
             _field(fb, off, 31, nb1, 6))  # fmt: skip
    work = Work(_field(fb, off, 18, nb1, 4), _field(fb, off, 19, nb1, 4),
            _blocks(fb, off, 20, n, 6),
            _blocks(fb, off, 21, nb1, 6), _blocks(fb, off, 22, nb1, 6),
            _field(fb, off, 23, nb1, 6), _field(fb, off, 24, nb1, 6),
            _field(fb, off, 25, nb1, 6), _blocks(fb, off, 26, n, 3), _blocks(fb, off, 27, n, 6),
            _field(fb, off, 28, n, 3), _field(fb, off, 29, n, 9))  # fmt: skip
    return tree, model, state, work


@kernel(error_model="numpy")
def _all_views(fb, ib):
    """``views`` for Python (``python_views``: never kept as they are)."""
    return views(fb, ib)


def python_views(fb: np.ndarray, ib: np.ndarray) -> tuple:
    """``views``' tuples as numpy views of fb that keep it alive (what Python holds)."""
    base = fb.ctypes.data

    def own(a):
        start = (a.ctypes.data - base) // fb.itemsize
        return fb[start : start + a.size].reshape(a.shape)

    tree, *rest = _all_views(fb, ib)
    start = [(a.ctypes.data - ib.ctypes.data) // ib.itemsize for a in tree]
    return (Tree(*(ib[k : k + len(a)] for k, a in zip(start, tree, strict=True))),
            *(type(group)(*(own(a) for a in group)) for group in rest))  # fmt: skip


@kernel(error_model="numpy", inline="always")
def rotm(q):
    """The rotation matrix of unit quaternion q, as nested tuples (rows)."""
    w, x, y, z = q
    return (
        (1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)),
        (2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)),
        (2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)),
    )


@kernel(error_model="numpy", inline="always")
def _rot(R, v):
    """R v for a rotation matrix of nested tuples (``rotm``), when R is made anyway."""
    return (
        R[0][0] * v[0] + R[0][1] * v[1] + R[0][2] * v[2],
        R[1][0] * v[0] + R[1][1] * v[1] + R[1][2] * v[2],
        R[2][0] * v[0] + R[2][1] * v[1] + R[2][2] * v[2],
    )


@kernel(error_model="numpy", inline="always")
def _mul3(M, k, i, a, b, c):
    """Row i of the 3-column block M[k] times (a, b, c)."""
    return M[k, i, 0] * a + M[k, i, 1] * b + M[k, i, 2] * c


@kernel(error_model="numpy", inline="always")
def _udinv(U, Dinv, k, i, col):
    """(U D⁻¹)[i, col] of joint k."""
    d = Dinv[k]
    return U[k, i, 0] * d[0, col] + U[k, i, 1] * d[1, col] + U[k, i, 2] * d[2, col]


@kernel(error_model="numpy", inline="always")
def _joint_motion(Q, Om, rest, k, c, p, Rp):
    """Joint k's rate Rpᵀ(ω_c − ω_p) and deflection log(q_p⁻¹ q_c ⊗ rest⁻¹) (parent frame;
    Rp: the parent's rotation matrix, ``rotm``)."""
    dw = (Om[c, 0] - Om[p, 0], Om[c, 1] - Om[p, 1], Om[c, 2] - Om[p, 2])
    rate = (Rp[0][0] * dw[0] + Rp[1][0] * dw[1] + Rp[2][0] * dw[2],
            Rp[0][1] * dw[0] + Rp[1][1] * dw[1] + Rp[2][1] * dw[2],
            Rp[0][2] * dw[0] + Rp[1][2] * dw[1] + Rp[2][2] * dw[2])  # fmt: skip
    rel = qmul(qmul(qconj(quat_at(Q, p)), quat_at(Q, c)), qconj(quat_at(rest, k)))
    return rate, qlog(rel)


@kernel(error_model="numpy", inline="always")
def _grip_force(grip, point, rate, tail):
    """The grip spring-damper's force on its point (position, velocity), the target taken
    ``tail`` before the step's end (back along its velocity)."""
    k, d, t, v = grip[GRIP_K], grip[GRIP_D], GRIP_TARGET, GRIP_RATE
    return (
        -k * (point[0] - grip[t] + tail * grip[v]) - d * (rate[0] - grip[v]),
        -k * (point[1] - grip[t + 1] + tail * grip[v + 1]) - d * (rate[1] - grip[v + 1]),
        -k * (point[2] - grip[t + 2] + tail * grip[v + 2]) - d * (rate[2] - grip[v + 2]),
    )


@kernel(error_model="numpy", inline="always")
def place(tree, model, Q, X):
    """Each tree joint's child placed by the joint: X[child] = anchor − R_c·anchor_child,
    the anchor on the parent at X[parent] + R_p·anchor_parent."""
    child, parent = tree.child, tree.parent
    ap, ac = model.anchor_parent, model.anchor_child
    for k in range(len(child)):
        c, p = child[k], parent[k]
        a = add(vec(X, p), qrotate(quat_at(Q, p), vec(ap, k)))
        lever = qrotate(quat_at(Q, c), vec(ac, k))
        for i in range(3):
            X[c, i] = a[i] - lever[i]


@kernel(error_model="numpy")
def spatial_inertia(R, ib, m, x, out):
    """The 6×6 spatial inertia at the step's origin (angular first) of a body of mass m,
    body-frame inertia ib about its centre x, turned by R."""
    for i in range(3):
        for j in range(3):
            s = 0.0
            for k in range(3):
                s += R[i][k] * (R[j][0] * ib[k, 0] + R[j][1] * ib[k, 1] + R[j][2] * ib[k, 2])
            out[i, j] = s + m * ((x[0] * x[0] + x[1] * x[1] + x[2] * x[2]) * (i == j) - x[i] * x[j])
            out[3 + i, 3 + j] = m * (i == j)
    out[0, 3], out[0, 4], out[0, 5] = 0.0, -m * x[2], m * x[1]
    out[1, 3], out[1, 4], out[1, 5] = m * x[2], 0.0, -m * x[0]
    out[2, 3], out[2, 4], out[2, 5] = -m * x[1], m * x[0], 0.0
    for i in range(3):
        for j in range(3):
            out[3 + j, i] = out[i, 3 + j]


@kernel(error_model="numpy", inline="always")
def _predict(tree, state, work, c_bdf, gam):
    """q̂ = exp(c·log(q q_prev⁻¹)) ⊗ q and the predicted q̃ = exp(γω) ⊗ q̂ of every child."""
    Q, Qp, Om = state.quat, state.quat_prev, state.omega
    Qh, Qs = work.quat_hat, work.quat_pred
    for c in tree.child:
        qc = quat_at(Q, c)
        qh = qmul(qexp(scale(c_bdf, qlog(qmul(qc, qconj(quat_at(Qp, c)))))), qc)
        qs = qnormalize(qmul(qexp(scale(gam, vec(Om, c))), qh))
        for i in range(4):
            Qh[c, i] = qh[i]
            Qs[c, i] = qs[i]


@kernel(error_model="numpy", inline="always")
def _linearise(tree, model, state, work, c_bdf, gam):
    """At the predicted pose: placements, motion subspaces S, relative rates u*, spring
    deflections, spatial inertias, V* and each body's residual f = Φ V* − Ĥ − γW (W: gravity
    and the loads, as a wrench at the origin)."""
    child, parent = tree.child, tree.parent
    ap, ac, _, _, mass, ibody, opt = model
    P, Pp, X, anchor, loads = state.momentum, state.momentum_prev, state.pos, state.rest, \
        state.loads  # fmt: skip
    Qs, S, I6, V, f, wk = (
        work.quat_pred,
        work.motion,
        work.inertia,
        work.velocity,
        work.residual,
        work.rates,
    )
    Om = state.omega
    g = (opt[OPT_GRAVITY], opt[OPT_GRAVITY + 1], opt[OPT_GRAVITY + 2])
    for k in range(len(child)):
        c, p = child[k], parent[k]
        Rp, Rc = rotm(quat_at(Qs, p)), rotm(quat_at(Qs, c))
        a = add(vec(X, p), _rot(Rp, vec(ap, k)))
        lever = _rot(Rc, vec(ac, k))
        x = (a[0] - lever[0], a[1] - lever[1], a[2] - lever[2])
        for i in range(3):
            X[c, i] = x[i]
        for col in range(3):
            e = (Rp[0][col], Rp[1][col], Rp[2][col])
            lin = cross(a, e)
            for i in range(3):
                S[k, i, col] = e[i]
                S[k, 3 + i, col] = lin[i]
        rate, th = _joint_motion(Qs, Om, anchor, k, c, p, Rp)
        for i in range(3):
            wk[k, i] = rate[i]
            wk[k, 3 + i] = th[i]
        m = mass[c]
        spatial_inertia(Rc, ibody[c], m, x, I6[c])
        for i in range(6):
            V[c, i] = V[p, i] + _mul3(S, k, i, wk[k, 0], wk[k, 1], wk[k, 2])
        ph = (P[c, 3] + c_bdf * (P[c, 3] - Pp[c, 3]), P[c, 4] + c_bdf * (P[c, 4] - Pp[c, 4]),
              P[c, 5] + c_bdf * (P[c, 5] - Pp[c, 5]))  # fmt: skip
        lh = (P[c, 0] + c_bdf * (P[c, 0] - Pp[c, 0]), P[c, 1] + c_bdf * (P[c, 1] - Pp[c, 1]),
              P[c, 2] + c_bdf * (P[c, 2] - Pp[c, 2]))  # fmt: skip
        lo = add(lh, cross(x, ph))
        mg = scale(m, g)
        tg = cross(x, mg)
        for i in range(6):
            s = 0.0
            for j in range(6):
                s += I6[c, i, j] * V[c, j]
            f[c, i] = s
        for i in range(3):
            f[c, i] -= lo[i] + gam * tg[i]
            f[c, 3 + i] -= ph[i] + gam * mg[i]
        tl = cross(x, (loads[c, 3], loads[c, 4], loads[c, 5]))  # the loads' moment at O
        for i in range(3):
            f[c, i] -= gam * (loads[c, i] + tl[i])
            f[c, 3 + i] -= gam * loads[c, 3 + i]


@kernel(error_model="numpy", inline="always")
def _grip(state, work, grip, tail, gam):
    """The grip spring at the predicted pose: γ·its wrench into the body's residual and
    γ(d + γk)·GᵀG (G = [−[p]×, I], p the grip point) into its articulated inertia.
    tail: time from this part's end to the step's end (the target moves back along its
    velocity)."""
    b = int(grip[GRIP_BODY])
    if b < 0:
        return
    Qs, X, V, f, IA = work.quat_pred, state.pos, work.velocity, work.residual, work.articulated
    p = add(vec(X, b), qrotate(quat_at(Qs, b), vec_from(grip, GRIP_ANCHOR)))
    pd = add(vec_from(V[b], 3), cross(vec(V, b), p))
    fg = _grip_force(grip, p, pd, tail)
    k, d = grip[GRIP_K], grip[GRIP_D]
    mo = cross(p, fg)
    for i in range(3):
        f[b, i] -= gam * mo[i]
        f[b, 3 + i] -= gam * fg[i]
    kk = gam * (d + gam * k)
    pp = p[0] * p[0] + p[1] * p[1] + p[2] * p[2]
    for i in range(3):
        for j in range(3):
            IA[b, i, j] += kk * (pp * (i == j) - p[i] * p[j])
        IA[b, 3 + i, 3 + i] += kk
    for i, j, s in ((0, 4, -p[2]), (0, 5, p[1]), (1, 3, p[2]), (1, 5, -p[0]), (2, 3, -p[1]),
                    (2, 4, p[0])):  # fmt: skip
        IA[b, i, j] += kk * s
        IA[b, j, i] += kk * s


@kernel(error_model="numpy", inline="always")
def _articulate(tree, model, work, gam):
    """The backward pass: each joint's 3×3 pivot D = SᵀI^A S + γ(D_f + γK_f) (inverted),
    U = I^A S and bias, and the articulated inertias and biases passed to the parents."""
    child, parent = tree.child, tree.parent
    kf, df = model.kf, model.df
    _, _, S, _, IA, pA, _, f, Dinv, U, uu, wk = work
    for k in range(len(child) - 1, -1, -1):
        c, p = child[k], parent[k]
        for i in range(6):
            f[p, i] += f[c, i]
        for col in range(3):
            tau = 0.0
            sp = 0.0
            for i in range(6):
                tau += S[k, i, col] * f[c, i]
                sp += S[k, i, col] * pA[c, i]
            uu[k, col] = gam * (-kf[k, col] * wk[k, 3 + col] - df[k, col] * wk[k, col]) - tau - sp
        for i in range(6):
            for col in range(3):
                s = 0.0
                for j in range(6):
                    s += IA[c, i, j] * S[k, j, col]
                U[k, i, col] = s
        m00 = m01 = m02 = m11 = m12 = m22 = 0.0
        for i in range(6):
            m00 += S[k, i, 0] * U[k, i, 0]
            m01 += S[k, i, 0] * U[k, i, 1]
            m02 += S[k, i, 0] * U[k, i, 2]
            m11 += S[k, i, 1] * U[k, i, 1]
            m12 += S[k, i, 1] * U[k, i, 2]
            m22 += S[k, i, 2] * U[k, i, 2]
        m00 += gam * (df[k, 0] + gam * kf[k, 0])
        m11 += gam * (df[k, 1] + gam * kf[k, 1])
        m22 += gam * (df[k, 2] + gam * kf[k, 2])
        c00, c01, c02 = m11 * m22 - m12 * m12, m02 * m12 - m01 * m22, m01 * m12 - m02 * m11
        idet = 1.0 / (m00 * c00 + m01 * c01 + m02 * c02)
        Dinv[k, 0, 0] = c00 * idet
        Dinv[k, 0, 1] = Dinv[k, 1, 0] = c01 * idet
        Dinv[k, 0, 2] = Dinv[k, 2, 0] = c02 * idet
        Dinv[k, 1, 1] = (m00 * m22 - m02 * m02) * idet
        Dinv[k, 1, 2] = Dinv[k, 2, 1] = (m01 * m02 - m00 * m12) * idet
        Dinv[k, 2, 2] = (m00 * m11 - m01 * m01) * idet
        for i in range(6):
            w0, w1 = _udinv(U, Dinv, k, i, 0), _udinv(U, Dinv, k, i, 1)
            w2 = _udinv(U, Dinv, k, i, 2)
            pA[p, i] += pA[c, i] + w0 * uu[k, 0] + w1 * uu[k, 1] + w2 * uu[k, 2]
            for j in range(i + 1):  # symmetric: the lower half, mirrored
                IA[p, i, j] += IA[c, i, j] - (w0 * U[k, j, 0] + w1 * U[k, j, 1] + w2 * U[k, j, 2])
                IA[p, j, i] = IA[p, i, j]


@kernel(error_model="numpy", inline="always")
def _finish(tree, model, state, work, gam):
    """The forward pass: δu per joint, the new relative rates u = u* + δu and body
    velocities V = J u at the predicted pose; the momenta kept for the next step are
    those (at the predicted pose: kept at the end pose they would make the step first
    order); new orientations q = exp(γω) ⊗ q̂."""
    child, parent = tree.child, tree.parent
    mass = model.mass
    Q, Qp, Om, P, Pp, X = (
        state.quat,
        state.quat_prev,
        state.omega,
        state.momentum,
        state.momentum_prev,
        state.pos,
    )
    Qh, _, S, I6, _, pA, V, _, Dinv, U, uu, wk = work
    for k in range(len(child)):
        c, p = child[k], parent[k]
        e0, e1, e2 = uu[k, 0], uu[k, 1], uu[k, 2]
        for i in range(6):
            e0 -= U[k, i, 0] * V[p, i]
            e1 -= U[k, i, 1] * V[p, i]
            e2 -= U[k, i, 2] * V[p, i]
        w0, w1, w2 = _mul3(Dinv, k, 0, e0, e1, e2), _mul3(Dinv, k, 1, e0, e1, e2), \
            _mul3(Dinv, k, 2, e0, e1, e2)  # fmt: skip
        for i in range(6):
            V[c, i] = V[p, i] + _mul3(S, k, i, w0, w1, w2)
        wk[k, 6], wk[k, 7], wk[k, 8] = wk[k, 0] + w0, wk[k, 1] + w1, wk[k, 2] + w2
    for k in range(len(child)):
        c, p = child[k], parent[k]
        for i in range(6):
            pA[c, i] = pA[p, i] + _mul3(S, k, i, wk[k, 6], wk[k, 7], wk[k, 8])
        wc = vec(pA, c)
        x = vec(X, c)
        vc = add(vec_from(pA[c], 3), cross(wc, x))
        for i in range(3):
            Pp[c, i], Pp[c, 3 + i] = P[c, i], P[c, 3 + i]
            s = 0.0
            for j in range(6):
                s += I6[c, i, j] * pA[c, j]
            P[c, i] = s
            P[c, 3 + i] = mass[c] * vc[i]
            Om[c, i] = wc[i]
        about_centre = cross(x, vec_from(P[c], 3))
        for i in range(3):
            P[c, i] -= about_centre[i]
        qn = qnormalize(qmul(qexp(scale(gam, wc)), quat_at(Qh, c)))
        for i in range(4):
            Qp[c, i] = Q[c, i]
            Q[c, i] = qn[i]


@kernel(error_model="numpy", inline="always")
def part(tree, model, state, work, h, r, grip, tail):
    """One BDF2 part of length h at step ratio r = h/h_prev (r = 0: backward Euler, no
    history); tail: the time from its end to the whole step's end (the grip's target).
    The bodies' positions are left at the predicted pose (``advance`` places them at the
    step's end)."""
    c_bdf = r * r / (1.0 + 2.0 * r)
    gam = h * (1.0 + r) / (1.0 + 2.0 * r)
    work.velocity[:] = 0.0  # the fixed bodies' stay 0
    work.bias[:] = 0.0
    work.residual[:] = 0.0
    _predict(tree, state, work, c_bdf, gam)
    _linearise(tree, model, state, work, c_bdf, gam)
    work.articulated[:] = work.inertia
    _grip(state, work, grip, tail, gam)
    _articulate(tree, model, work, gam)
    work.bias[:] = 0.0  # (the fixed bodies' took their children's)
    _finish(tree, model, state, work, gam)
    state.clock[CLOCK_HPREV] = h


@kernel(error_model="numpy")
def _outputs(tree, model, state, grip):
    """What the State and the report show: each body's velocity (p/m), each joint's
    deflection and spring-damper torque, the grip's force on its bone."""
    child, parent, joint = tree.child, tree.parent, tree.joint
    kf, df, mass = model.kf, model.df, model.mass
    Q, _, Om, P, _, X, Vl, anchor, delta, torque, clock, world, _ = state
    origin = model.options[OPT_ORIGIN : OPT_ORIGIN + 3]
    for k in range(len(child)):
        c, p, j = child[k], parent[k], joint[k]
        for i in range(3):
            Vl[c, i] = P[c, 3 + i] / mass[c]
            world[c, i] = X[c, i] + origin[i]
        rate, th = _joint_motion(Q, Om, anchor, k, c, p, rotm(quat_at(Q, p)))
        for i in range(3):
            delta[j, i] = th[i]
            torque[j, i] = -kf[k, i] * th[i] - df[k, i] * rate[i]
    b = int(grip[GRIP_BODY])
    force = (0.0, 0.0, 0.0)
    if b >= 0:
        lever = qrotate(quat_at(Q, b), vec_from(grip, GRIP_ANCHOR))
        rate = add(vec(Vl, b), cross(vec(Om, b), lever))
        force = _grip_force(grip, add(vec(X, b), lever), rate, 0.0)
    for i in range(3):
        clock[CLOCK_GRIP_FORCE + i] = force[i]


@kernel(error_model="numpy", inline="always")
def _broken(tree, model, state):
    """The first child body whose state is not finite or moves beyond the model's speed
    limits, or -1."""
    opt, mass = model.options, model.mass
    Q, Om, X, P = state.quat, state.omega, state.pos, state.momentum
    for c in tree.child:
        v2 = (P[c, 3] ** 2 + P[c, 4] ** 2 + P[c, 5] ** 2) / (mass[c] * mass[c])
        w2 = Om[c, 0] ** 2 + Om[c, 1] ** 2 + Om[c, 2] ** 2
        s = v2 + w2 + X[c, 0] + X[c, 1] + X[c, 2] + Q[c, 0] + Q[c, 1] + Q[c, 2] + Q[c, 3]
        if not math.isfinite(s):
            return c
        if v2 > opt[OPT_MAX_SPEED] ** 2 or w2 > opt[OPT_MAX_SPIN] ** 2:
            return c
    return -1


@kernel(error_model="numpy")
def advance(fb, ib, parts, grip):
    """A whole step in parts: parts (m, 2) holds each part's length and step ratio (0: no
    history).  OK, or BROKEN when the state is no longer finite or moves beyond the speed
    limits (the caller names the body: solver.advance.monitor).  What the state shows
    beyond the poses, omegas and momenta is made by ``refresh`` when it is read."""
    tree, model, state, work = views(fb, ib)
    total = 0.0
    for i in range(parts.shape[0]):
        total += parts[i, 0]
    done = 0.0
    for i in range(parts.shape[0]):
        done += parts[i, 0]
        part(tree, model, state, work, parts[i, 0], parts[i, 1], grip, total - done)
    place(tree, model, state.quat, state.pos)  # a part's linearisation places its own pose
    return OK if _broken(tree, model, state) < 0 else BROKEN


@kernel(error_model="numpy")
def refresh(fb, ib, grip):
    """The outputs of the last step (``_outputs``), made when they are read (a loop that
    reads the state every few steps does not pay for them every step)."""
    tree, model, state, _ = views(fb, ib)
    _outputs(tree, model, state, grip)
