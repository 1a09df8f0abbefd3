"""The continuous equations of a rig with spring-damper ball joints, integrated to 1e-12:
the truth that the like-for-like accuracy study (``puppetcli.bench.likeforlike``)
measures puppetcli and MuJoCo against.

Written apart from both engines: reduced (joint) coordinates where both use maximal
(puppetcli) or their own recursive algorithms (MuJoCo), rotations by scipy, no solver
code.  Only the rig's data (masses, inertias, anchors, K, D) comes from the Model.

Coordinates.  Every joint j whose child c is movable has q_j = q_p⁻¹ ⊗ q_c (the child's
orientation in its parent's frame; identity at rest, where every body frame is world-
aligned with its origin at the centre of mass) and u_j, the child's angular velocity
relative to the parent in the parent's frame.  A static parent (the fixed root) has its
rest pose.  Then, parents before children, with R_p the parent's rotation, a the
joint's world anchor, r_pa = a − x_p and r_ac = x_c − a:

    R_c = R_p R(q_j),  ω_c = ω_p + R_p u_j,  x_c = a − R_c·anchor_child,
    v_c = v_p + ω_p × r_pa + ω_c × r_ac,
    q̇_j = ½ u_j ⊗ q_j                                  (u_j in the parent's frame)

and the accelerations at u̇ = 0 (the velocity-product terms):

    α⁰_c = α⁰_p + ω_p × (R_p u_j)
    a⁰_c = a⁰_p + α⁰_p × r_pa + ω_p × (ω_p × r_pa) + α⁰_c × r_ac + ω_c × (ω_c × r_ac).

A unit u̇_j,k turns every body b below j by R_p e_k about a: ∂ω_b = R_p e_k,
∂v_b = R_p e_k × (x_b − a).  With those Jacobians J_b (6 × 3n), Newton–Euler projected
on the joint coordinates (Kane's equations):

    M u̇ = Q + Σ_b J_bᵀ [m_b g + F_b − m_b a⁰_b ;  T_b − I_b α⁰_b − ω_b × I_b ω_b],
    M = Σ_b J_bᵀ diag(m_b, I_b) J_b,

I_b the world inertia.  The joint's generalised force is its torque in the parent's
frame, Q_j = −K_j log(q_j) − D_j u_j: the Voigt joint both engines model (K, D per
axis; the study uses equal axes, where the spring is conservative with potential
½K|log q_j|², and energy is conserved with D = 0: tests/puppetcli/bench/test_truth.py).
F_b, T_b: a spring-damper pulling a point of one bone towards a moving target (the
grip scene), F = −K_g (p − P(t)) − D_g (ṗ − U(t)), T = (p − x_b) × F.

A frictionless floor under a point p of one bone (the contact scene): while it presses,
p stays on the plane y = height, a holonomic constraint g(q) = p_y − height = 0 whose
force is vertical, N ≥ 0.  With G = ∂ṗ_y/∂u (a row of the point's Jacobian) the
equations become

    [ M  −Gᵀ ] [u̇]   [      Q + …       ]
    [ G   0  ] [N ] = [ −(velocity-product part of p̈_y) ],

so p̈_y = 0 exactly: started on the plane at rest, p stays on it to the integration's
tolerance.  The constraint is bilateral here; ``floor_force`` returns N, which the scene
checks stays positive (the contact never lets go), so the bilateral and the unilateral
contact have the same solution.  A frictionless constraint does no work: energy is
conserved with D = 0 (tests/puppetcli/bench/test_truth.py).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numba
import numpy as np
import scipy.integrate
from scipy.spatial.transform import Rotation

from solver.model import Model

TIGHT = dict(method="DOP853", rtol=1e-12, atol=1e-12)


@dataclass(frozen=True)
class Pull:
    """A spring-damper from a point of a bone to a moving target.

    body: body index; point (3,): in the body's frame from its centre of mass (m);
    stiffness N/m, damping N·s/m; target(t) → (P (3,) m, U (3,) m/s).
    """

    body: int
    point: np.ndarray
    stiffness: float
    damping: float
    target: Callable[[float], tuple[np.ndarray, np.ndarray]]


@dataclass(frozen=True)
class Floor:
    """A frictionless floor under a point of one bone (module docstring): body index,
    point (3,) in the body's frame from its centre of mass (m), and the height (m) of
    the plane y = height the point stays on."""

    body: int
    point: np.ndarray
    height: float


@dataclass(frozen=True)
class Tree:
    """The rig in joint coordinates: the joints of movable children, parents first.

    joint (n,): the Model's joint indices; child, parent (n,): body indices (parent may
    be static or −1, the world); below (nb, n) bool: body b moves with joint k.
    """

    model: Model
    joint: np.ndarray
    child: np.ndarray
    parent: np.ndarray
    below: np.ndarray


def make_tree(model: Model) -> Tree:
    """The joint-coordinate tree of ``model`` (every movable body hangs from one joint)."""
    movable = model.body_inv_mass > 0.0
    by_child = {int(c): j for j, c in enumerate(model.joint_bone) if movable[c]}
    if set(by_child) != set(np.flatnonzero(movable)):
        raise ValueError("every movable body must hang from exactly one joint")
    order: list[int] = []
    placed = set(np.flatnonzero(~movable)) | {-1}
    while len(order) < len(by_child):
        for c, j in by_child.items():
            if c not in placed and int(model.joint_parent[j]) in placed:
                order.append(j)
                placed.add(c)
    joint = np.array(order, dtype=int)
    child, parent = model.joint_bone[joint], model.joint_parent[joint]
    below = np.zeros((model.nbody, len(joint)), dtype=bool)
    for k in range(len(joint)):
        below[child[k], k] = True
        for k2 in range(k):  # parents come first: a child of a body below k2 is below k2
            below[child[k], k2] = below[parent[k], k2]
    return Tree(model, joint, child, parent, below)


def _rotation(q: np.ndarray) -> np.ndarray:
    return Rotation.from_quat(q, scalar_first=True).as_matrix()


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a × b over the last axis (numpy's cross costs ~10 µs a call on 3-vectors)."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack((a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0), axis=-1)


def _quat_left(u: np.ndarray, q: np.ndarray) -> np.ndarray:
    """(0, u) ⊗ q for rows of u (n,3) and q (n,4) (w,x,y,z)."""
    w, v = q[:, 0], q[:, 1:]
    return np.column_stack((-np.einsum("ni,ni->n", u, v), w[:, None] * u + _cross(u, v)))


def joint_state(tree: Tree, body_quat: np.ndarray, body_omega: np.ndarray) -> np.ndarray:
    """The ODE state [q (4n), u (3n)] of bodies' orientations and angular velocities."""
    qs = np.vstack((body_quat, [1.0, 0.0, 0.0, 0.0]))
    om = np.vstack((body_omega, np.zeros(3)))
    rel = Rotation.from_quat(qs[tree.parent], scalar_first=True).inv() * Rotation.from_quat(
        qs[tree.child], scalar_first=True
    )
    q = rel.as_quat(scalar_first=True)
    r_p = _rotation(qs[tree.parent])
    u = np.einsum("nji,nj->ni", r_p, om[tree.child] - om[tree.parent])
    return np.concatenate((q.reshape(-1), u.reshape(-1)))


@dataclass(frozen=True)
class Kinematics:
    """Bodies' world pose, velocities and velocity-product accelerations (nb, …) and
    the joints' world anchors and parent rotations (n, …)."""

    pos: np.ndarray
    rot: np.ndarray
    vel: np.ndarray
    omega: np.ndarray
    acc0: np.ndarray
    alpha0: np.ndarray
    anchor: np.ndarray
    rot_parent: np.ndarray


@numba.njit(cache=True)
def _down_the_tree(child, parent, anchor_p, anchor_c, rel, u, pos, rot, vel, omega, acc0, alpha0,
                   anchor, rot_parent):  # fmt: skip
    """The recursion of the module docstring, parents first (compiled: in Python its ~30
    small vector operations a joint were 3/4 of the doll's derivative)."""
    for k in range(len(child)):
        c, p = child[k], parent[k]
        r_p = rot[p].copy()
        rot[c] = r_p @ rel[k]
        a = pos[p] + r_p @ anchor_p[k]
        pos[c] = a - rot[c] @ anchor_c[k]
        r_pa, r_ac = a - pos[p], pos[c] - a
        w_rel = r_p @ u[k]
        omega[c] = omega[p] + w_rel
        vel[c] = vel[p] + np.cross(omega[p], r_pa) + np.cross(omega[c], r_ac)
        alpha0[c] = alpha0[p] + np.cross(omega[p], w_rel)
        acc0[c] = (
            acc0[p]
            + np.cross(alpha0[p], r_pa)
            + np.cross(omega[p], np.cross(omega[p], r_pa))
            + np.cross(alpha0[c], r_ac)
            + np.cross(omega[c], np.cross(omega[c], r_ac))
        )
        anchor[k], rot_parent[k] = a, r_p


def kinematics(tree: Tree, q: np.ndarray, u: np.ndarray) -> Kinematics:
    """Forward kinematics of joint coordinates q (n,4) (normalised here) and u (n,3)."""
    m = tree.model
    nb = m.nbody
    pos = np.vstack((m.body_pos0, np.zeros(3)))  # static bodies keep their rest pose; -1 world
    rot = np.concatenate((_rotation(m.body_quat0), np.eye(3)[None]))
    vel, omega, acc0, alpha0 = (np.zeros((nb + 1, 3)) for _ in range(4))
    rel = _rotation(q / np.linalg.norm(q, axis=1, keepdims=True))
    anchor = np.zeros((len(tree.joint), 3))
    rot_parent = np.zeros((len(tree.joint), 3, 3))
    _down_the_tree(
        tree.child, tree.parent, m.joint_anchor_parent[tree.joint],
        m.joint_anchor_child[tree.joint], rel, np.ascontiguousarray(u), pos, rot, vel, omega,
        acc0, alpha0, anchor, rot_parent,
    )  # fmt: skip
    return Kinematics(
        pos[:nb], rot[:nb], vel[:nb], omega[:nb], acc0[:nb], alpha0[:nb], anchor, rot_parent
    )


def _jacobians(tree: Tree, kin: Kinematics) -> tuple[np.ndarray, np.ndarray]:
    """∂v_b/∂u and ∂ω_b/∂u, each (nb, 3, 3n)."""
    n = len(tree.joint)
    axes = kin.rot_parent  # (n,3,3): column k is R_p e_k
    jw = np.where(tree.below[:, :, None, None], axes[None], 0.0)  # (nb,n,3,3)
    lever = kin.pos[:, None, :] - kin.anchor[None, :, :]  # (nb,n,3)
    jv = _cross(np.swapaxes(jw, 2, 3), lever[:, :, None, :])  # rows: (R_p e_k) × lever
    jv = np.swapaxes(jv, 2, 3)
    nb = len(kin.pos)
    return (
        np.transpose(jv, (0, 2, 1, 3)).reshape(nb, 3, 3 * n),
        np.transpose(jw, (0, 2, 1, 3)).reshape(nb, 3, 3 * n),
    )


def energy(tree: Tree, y: np.ndarray) -> float:
    """Kinetic + gravitational + joint-spring energy (J) of state y (no Pull)."""
    m = tree.model
    n = len(tree.joint)
    q, u = y[: 4 * n].reshape(n, 4), y[4 * n :].reshape(n, 3)
    kin = kinematics(tree, q, u)
    movable = m.body_inv_mass > 0.0
    inertia_w = kin.rot @ m.body_inertia @ np.swapaxes(kin.rot, 1, 2)
    kinetic = 0.5 * np.sum(m.body_mass[movable] * np.sum(kin.vel[movable] ** 2, axis=1))
    kinetic += 0.5 * np.einsum("ni,nij,nj->", kin.omega, inertia_w, kin.omega)
    gravity = -np.sum(m.body_mass[movable] * (kin.pos[movable] @ m.options.gravity))
    theta = Rotation.from_quat(q, scalar_first=True).as_rotvec()
    spring = 0.5 * np.sum(m.joint_kf[tree.joint] * theta**2)
    return float(kinetic + gravity + spring)


def derivative(
    tree: Tree, t: float, y: np.ndarray, pull: Pull | None = None, floor: Floor | None = None
) -> np.ndarray:
    """dy/dt of the state y = [q (4n), u (3n)] at time t."""
    q, u, kin, (mass_matrix, rhs, jv, jw) = _equations(tree, t, y, pull)
    if floor is None:
        udot = np.linalg.solve(mass_matrix, rhs)
    else:
        udot, _ = _on_the_floor(mass_matrix, rhs, jv, jw, kin, floor)
    qdot = 0.5 * _quat_left(u, q)
    return np.concatenate((qdot.reshape(-1), udot))


def floor_force(tree: Tree, t: float, y: np.ndarray, floor: Floor,
                pull: Pull | None = None) -> float:  # fmt: skip
    """N (newtons): the floor's push on the point at state y (negative: it would pull)."""
    _, _, kin, (mass_matrix, rhs, jv, jw) = _equations(tree, t, y, pull)
    return _on_the_floor(mass_matrix, rhs, jv, jw, kin, floor)[1]


def _equations(tree: Tree, t: float, y: np.ndarray, pull: Pull | None) -> tuple:
    """(q, u, kinematics, (M, Q + Σ J_bᵀ(…), ∂v/∂u, ∂ω/∂u)) at state y: M u̇ = rhs
    without constraints."""
    m = tree.model
    n = len(tree.joint)
    q, u = y[: 4 * n].reshape(n, 4), y[4 * n :].reshape(n, 3)
    kin = kinematics(tree, q, u)
    jv, jw = _jacobians(tree, kin)
    movable = m.body_inv_mass > 0.0
    mass = np.where(movable, m.body_mass, 0.0)
    inertia_w = kin.rot @ m.body_inertia @ np.swapaxes(kin.rot, 1, 2)
    inertia_w[~movable] = 0.0
    force = mass[:, None] * (m.options.gravity - kin.acc0)
    torque = -np.einsum("nij,nj->ni", inertia_w, kin.alpha0) - _cross(
        kin.omega, np.einsum("nij,nj->ni", inertia_w, kin.omega)
    )
    if pull is not None:
        b = pull.body
        lever = kin.rot[b] @ pull.point
        p, pdot = kin.pos[b] + lever, kin.vel[b] + _cross(kin.omega[b], lever)
        target, target_vel = pull.target(t)
        f = -pull.stiffness * (p - target) - pull.damping * (pdot - target_vel)
        force[b] += f
        torque[b] += _cross(lever, f)
    mass_matrix = np.einsum("b,bik,bil->kl", mass, jv, jv) + np.einsum(
        "bik,bij,bjl->kl", jw, inertia_w, jw
    )
    theta = Rotation.from_quat(q, scalar_first=True).as_rotvec()
    gen = -m.joint_kf[tree.joint] * theta - m.joint_df[tree.joint] * u
    rhs = gen.reshape(-1) + np.einsum("bik,bi->k", jv, force) + np.einsum("bik,bi->k", jw, torque)
    return q, u, kin, (mass_matrix, rhs, jv, jw)


def _on_the_floor(mass_matrix: np.ndarray, rhs: np.ndarray, jv: np.ndarray, jw: np.ndarray,
                  kin: Kinematics, floor: Floor) -> tuple[np.ndarray, float]:  # fmt: skip
    """(u̇, N) with the floor's constraint p̈_y = 0 (module docstring)."""
    b = floor.body
    lever = kin.rot[b] @ floor.point
    up = np.array([0.0, 1.0, 0.0])
    row = jv[b][1] + _cross(lever, up) @ jw[b]  # ∂ṗ_y/∂u: e_y·(δv + δω × lever)
    omega = kin.omega[b]
    acc0 = kin.acc0[b] + _cross(kin.alpha0[b], lever) + _cross(omega, _cross(omega, lever))
    k = len(rhs)
    kkt = np.zeros((k + 1, k + 1))
    kkt[:k, :k], kkt[:k, k], kkt[k, :k] = mass_matrix, -row, row
    sol = np.linalg.solve(kkt, np.append(rhs, -acc0[1]))
    return sol[:k], float(sol[k])


def integrate(
    tree: Tree, y0: np.ndarray, times: np.ndarray, pull: Pull | None = None,
    floor: Floor | None = None, **tolerances,
) -> np.ndarray:  # fmt: skip
    """States (len(times), 7n) at ``times`` from y0 at t = 0 (DOP853, rtol = atol = 1e-12)."""
    opts = {**TIGHT, **tolerances}
    sol = scipy.integrate.solve_ivp(
        lambda t, y: derivative(tree, t, y, pull, floor), (0.0, float(times[-1])), y0,
        t_eval=times, **opts,
    )  # fmt: skip
    if not sol.success:
        raise RuntimeError(f"the reference integration failed: {sol.message}")
    return sol.y.T


def body_poses(tree: Tree, ys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World positions (nt, nb, 3) and orientations (nt, nb, 4) (w,x,y,z) of states ys."""
    n = len(tree.joint)
    pos, quats = [], []
    for y in ys:
        kin = kinematics(tree, y[: 4 * n].reshape(n, 4), y[4 * n :].reshape(n, 3))
        pos.append(kin.pos)
        quats.append(Rotation.from_matrix(kin.rot).as_quat(scalar_first=True))
    return np.array(pos), np.array(quats)
