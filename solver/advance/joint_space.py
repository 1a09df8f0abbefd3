"""Joint-space steps: a tree of spring-damper ball joints stepped in its joint coordinates.

A model whose moving bodies hang in one tree of Voigt ball joints (no series damper,
limits, collisions or free bodies), stepped with ``integrator: bdf2``, needs none of the
maximal-coordinate machinery: no anchor rows (the joints cannot come apart), no contact,
no LCP.  Its unknowns are then 3 a joint, u_j: the child's angular velocity relative to
its parent, in the parent's frame (the rows' rate w_k = a_k·(ω_c − ω_p)); the bodies'
velocities are V = J u (spatial, about one point O, the tree's first fixed anchor: V_b =
(ω_b, v at O)); their positions, taken from O, follow from the joints.

**The step** is the same BDF2 as solver.advance.bdf2, on the same momenta.  With r =
h/h_prev, c = r²/(1 + 2r), γ = h(1 + r)/(1 + 2r), each body's world quantities are
extrapolated (q̂ = exp(c·log(q q_prev⁻¹)) ⊗ q; its momenta L about its centre and p =
m v: L̂ = L + c(L − L_prev), p̂ likewise), the step is linearised at the predicted pose
q̃ = exp(γω) ⊗ q̂ (bodies placed by the joints, motion subspaces S_j, inertias Φ_b, joint
rates u* and deflections θ*), and the momentum balance H[t+1] = Ĥ + γ·F[t+1], projected
on the joints by Jᵀ (the joints' reactions drop out), is

    (JᵀΦJ + γ(D + γK) + γ(d + γk)·JᵀGᵀGJ) δu = γ(−Kθ* − Du*) − Jᵀ(ΦV* − Ĥ − γW − γGᵀf*)

with u = u* + δu: the joints' springs and dampers K, D (θ[t+1] = θ* + γδu) and a grip's
spring-damper k, d on the point p of one bone (G = [−[p]×, I], f* its force at the
predicted pose) at t+1, gravity and the step's loads W = (x × (mg + F) + τ, mg + F).
The new orientations are q[t+1] = exp(γω) ⊗ q̂.  The momenta kept for the next step are
the solved ones at the predicted pose: re-evaluated at the end pose they differ by O(h²)
a step, which makes the step first order (measured on one link: the error halves, not
quarters, with h).  Taking BDF2 on u itself instead (a textbook choice) lets a bone's
twist leak into its children's relative rates: 13× the error on a chain bent in 3-D.

This module is the specification, solved densely (``reference_part``: numpy, every
matrix built whole).  The compiled twin (solver.advance.joint_space_kernel) solves the same
equations by the articulated-body recursion in O(n) (the joints' γ(D + γK) added to its
3×3 pivots, the grip's term to the gripped body's articulated inertia), allocation-free:
~2 µs a step for a 4-link chain, ~6 µs for the doll, against ~8 and ~16 in maximal
coordinates.

**Parts.**  A restart (the first step, or the first after the grip changed) is taken as
solver.advance.bdf2 takes one: backward Euler over h/4, then BDF2 over h/4 and h/2.  A
step longer than MAX_PART is taken in equal parts (its tests: tests/solver/test_joint_space.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.linalg import block_diag

from solver import quat
from solver.advance import joint_space_kernel as layout
from solver.advance.bdf2 import stage_length
from solver.advance.bdf2_kernel import R_MAX, RESTART
from solver.model import Model

MAX_PART = 0.04
"""The longest part of a step (s).  The linearisation at the predicted pose leaves the
change of gravity's and the springs' directions over the step explicit: the light chains
of ``puppetcli bench --accuracy`` (10 cm, 0.2 kg links) grow without bound from steps of
~50 ms taken whole.  Taken in parts of at most 40 ms, every scene there stays bounded at
every step from 40 to 250 ms (over 2 s, RMS at 1 and 2 s: the hanging chain 4.1–5.2 mm
from the truth, the one bent in 3-D 15–29 mm, the released doll 7–19 mm, the pulled doll
0.2–1.0 mm), at 26–41 parts a simulated second."""


@dataclass(frozen=True)
class JointTree:
    """The model's joints as a tree, parents before children: child (n,) and parent (n,)
    body (the world: nbody), joint (n,) the model's joint index."""

    child: np.ndarray
    parent: np.ndarray
    joint: np.ndarray


def unsupported(model: Model) -> str | None:
    """Why ``model`` cannot be stepped in joint space, or None when it can."""
    o = model.options
    flowing = model.joint_rheology & np.any(np.isfinite(model.joint_dd), axis=1)
    reasons = (
        (not o.joint_space, "switched off (Options.joint_space)"),
        (o.integrator != "bdf2", f"integrator {o.integrator}, not bdf2"),
        (model.has_collision, "its shapes can collide"),
        (model.has_limits, "its joints have limits"),
        (bool(flowing.any()), "its joints have series dampers (plastic)"),
    )
    for failed, why in reasons:
        if failed:
            return why
    try:
        tree(model)
    except ValueError as exc:
        return str(exc)
    return None


def tree(model: Model) -> JointTree:
    """The joint tree of ``model``: every moving body the child of exactly one joint, hung
    from a fixed body or the world (ValueError naming the body otherwise)."""
    nb = model.nbody
    moving = model.body_inv_mass > 0.0
    hung = {}
    for j, (c, p) in enumerate(zip(model.joint_bone, model.joint_parent, strict=True)):
        if not moving[c]:
            if p >= 0 and moving[p]:
                raise ValueError(f"fixed body '{model.body_names[c]}' hangs from a moving one")
            continue
        if c in hung:
            raise ValueError(f"body '{model.body_names[c]}' is the child of two joints")
        hung[int(c)] = j
    for b in np.flatnonzero(moving):
        if b not in hung:
            raise ValueError(f"body '{model.body_names[b]}' is free (no joint holds it)")
    order, placed = [], set(np.flatnonzero(~moving).tolist())
    while len(order) < len(hung):
        ready = [j for c, j in hung.items() if c not in placed and _parent(model, j, nb) in
                 placed | {nb}]  # fmt: skip
        if not ready:
            raise ValueError("the joints make a loop")
        for j in sorted(ready):
            order.append(j)
            placed.add(int(model.joint_bone[j]))
    joint = np.array(order, dtype=np.int64)
    parent = np.array([_parent(model, j, nb) for j in order], dtype=np.int64)
    return JointTree(model.joint_bone[joint].astype(np.int64), parent, joint)


def _parent(model: Model, j: int, nb: int) -> int:
    p = int(model.joint_parent[j])
    return nb if p < 0 else p


def part_length(h: float) -> float:
    """The length of each of the equal parts a step of h is taken in (h when h ≤ MAX_PART)."""
    return h / max(1, math.ceil(h / MAX_PART - 1e-9))


def parts(h: float, h_prev: float, restart: bool) -> np.ndarray:
    """A step's parts (m, 2): each one's length and step ratio (0: backward Euler): m equal
    parts, the first split as a restart's (RESTART) when asked or without a usable
    history (h_prev = 0, or a ratio above R_MAX)."""
    hp = part_length(h)
    m = round(h / hp)
    if not restart and h_prev > 0.0 and hp / h_prev <= R_MAX:
        head = [(hp, hp / h_prev)]
    else:
        head, done = [], 0.0
        for div in RESTART:
            head.append((hp / div, done and (hp / div) / done))
            done = hp / div
    rest = [(hp, (hp / head[-1][0]) if i == 0 else 1.0) for i in range(m - 1)]
    return np.array(head + rest, dtype=np.float64)


def _skew(x: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -x[2], x[1]], [x[2], 0.0, -x[0]], [-x[1], x[0], 0.0]])


def place(tree: tuple, ap: np.ndarray, ac: np.ndarray, Q: np.ndarray, X: np.ndarray) -> None:
    """Each child at its joint: X_c = X_p + R_p·anchor_parent − R_c·anchor_child (in place)."""
    for k, (c, p) in enumerate(zip(tree.child, tree.parent, strict=True)):
        X[c] = X[p] + quat.rotate(Q[p], ap[k]) - quat.rotate(Q[c], ac[k])


def reference_part(tree: tuple, model: tuple, state: tuple, h: float, r: float,
                   grip: np.ndarray, tail: float) -> None:  # fmt: skip
    """One BDF2 part (module docstring) of length h at step ratio r (0: backward Euler),
    solved densely; updates the state arrays (solver.advance.joint_space_kernel.views'
    tuples) in place.  grip: the kernel's grip vector; tail: the time from this part's
    end to the step's end."""
    child, parent = tree.child, tree.parent
    ap, ac, kf, df, mass, ibody, opt = model
    Q, Qp, Om, P, Pp, X = state.quat, state.quat_prev, state.omega, state.momentum, \
        state.momentum_prev, state.pos  # fmt: skip
    anchor = state.rest
    c_bdf, gam = r * r / (1.0 + 2.0 * r), stage_length(h, r)
    Qh, Qs = Q.copy(), Q.copy()
    for c in child:
        Qh[c] = quat.mul(quat.exp(c_bdf * quat.log(quat.mul(Q[c], quat.conj(Qp[c])))), Q[c])
        Qs[c] = quat.normalize(quat.mul(quat.exp(gam * Om[c]), Qh[c]))
    Xs = X.copy()
    place(tree, ap, ac, Qs, Xs)
    J = _jacobian(tree, ap, Qs, Xs)
    Phi = np.zeros((len(Q), 6, 6))
    W, Hh = np.zeros((len(Q), 6)), np.zeros((len(Q), 6))
    for c in child:
        x, m = Xs[c], mass[c]
        R = quat.matrix(Qs[c])
        Phi[c] = np.block([[R @ ibody[c] @ R.T - m * _skew(x) @ _skew(x), m * _skew(x)],
                           [-m * _skew(x), m * np.eye(3)]])  # fmt: skip
        Lh = P[c, :3] + c_bdf * (P[c, :3] - Pp[c, :3])
        ph = P[c, 3:] + c_bdf * (P[c, 3:] - Pp[c, 3:])
        Hh[c] = np.concatenate([Lh + np.cross(x, ph), ph])
        mg = m * opt[layout.OPT_GRAVITY : layout.OPT_GRAVITY + 3]
        torque, force = state.loads[c, :3], state.loads[c, 3:]
        W[c] = np.concatenate([np.cross(x, mg + force) + torque, mg + force])
    u_star = np.concatenate([quat.matrix(Qs[p]).T @ (Om[c] - Om[p])
                             for c, p in zip(child, parent, strict=True)])  # fmt: skip
    rel = [quat.mul(quat.conj(Qs[p]), Qs[c]) for c, p in zip(child, parent, strict=True)]
    theta = np.concatenate(
        [quat.log(quat.mul(q, quat.conj(a))) for q, a in zip(rel, anchor, strict=True)]
    )
    K, D = kf.ravel(), df.ravel()
    Phi_all = block_diag(*Phi)
    V_star = J @ u_star
    A = J.T @ Phi_all @ J + np.diag(gam * (D + gam * K))
    b = gam * (-K * theta - D * u_star) - J.T @ (Phi_all @ V_star - Hh.ravel() - gam * W.ravel())
    body = int(grip[layout.GRIP_BODY])
    if body >= 0:
        point = Xs[body] + quat.rotate(Qs[body], grip[layout.GRIP_ANCHOR : layout.GRIP_ANCHOR + 3])
        G = np.zeros((3, 6 * len(Q)))
        G[:, 6 * body : 6 * body + 3] = -_skew(point)
        G[:, 6 * body + 3 : 6 * body + 6] = np.eye(3)
        k, d = grip[layout.GRIP_K], grip[layout.GRIP_D]
        rate = grip[layout.GRIP_RATE : layout.GRIP_RATE + 3]
        target = grip[layout.GRIP_TARGET : layout.GRIP_TARGET + 3] - tail * rate
        f_star = -k * (point - target) - d * (G @ V_star - rate)
        A += gam * (d + gam * k) * (J.T @ G.T @ G @ J)
        b += gam * (J.T @ G.T @ f_star)
    u = u_star + np.linalg.solve(A, b)
    V = (J @ u).reshape(-1, 6)
    H = (Phi_all @ V.ravel()).reshape(-1, 6)
    for c in child:
        Pp[c], Qp[c] = P[c], Q[c]
        p_lin = mass[c] * (V[c, 3:] + np.cross(V[c, :3], Xs[c]))
        P[c] = np.concatenate([H[c, :3] - np.cross(Xs[c], H[c, 3:]), p_lin])
        Om[c] = V[c, :3]
        Q[c] = quat.normalize(quat.mul(quat.exp(gam * V[c, :3]), Qh[c]))
    place(tree, ap, ac, Q, X)
    state.clock[layout.CLOCK_HPREV] = h


def _jacobian(tree: tuple, ap: np.ndarray, Qs: np.ndarray, Xs: np.ndarray) -> np.ndarray:
    """J (6·bodies, 3n): body b's spatial velocity from the joint rates, S_k = (R_p,
    [a_k]×R_p) (a_k the joint's world anchor) for every joint k above b or at it."""
    child, parent = tree.child, tree.parent
    n, nb1 = len(child), len(Qs)
    above = {int(c): k for k, c in enumerate(child)}
    J = np.zeros((6 * nb1, 3 * n))
    for k, (c, p) in enumerate(zip(child, parent, strict=True)):
        Rp = quat.matrix(Qs[p])
        a = Xs[p] + Rp @ ap[k]
        S = np.vstack([Rp, _skew(a) @ Rp])
        for b in child:
            walk = int(b)
            while walk in above and walk != c:
                walk = int(parent[above[walk]])
            if walk == c:
                J[6 * b : 6 * b + 6, 3 * k : 3 * k + 3] = S
    return J
