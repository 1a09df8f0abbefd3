"""The haptic pointer: 6-DOF virtual coupling (grip mode) and touching (free mode).

The pointer is kinematic: the device sets its pose; nothing pushes it back.
``Pointer`` gives its pose at the END of the step and its velocity over the step.

Grip mode couples a point of a bone to the pointer with a spring-damper in
translation (3 rows, world axes, at the grip point) and in rotation (3 rows,
world axes), integrated implicitly inside the LCP as Voigt rows (see
solver.rows.compliance).  With e' = (bone now) − (pointer target at t+1) and u the
pointer's velocity, the backward-Euler spring-damper

    λ = −K (e' + h w) − D (w − u)
  ⇔ w + λ/(D + K h) + (K e' − D u)/(D + K h) = 0,

so C = 1/(D + K h) and bias = (K e' − D u)/(D + K h): stable for any K and h.
Rotation: e' = log(q_bone ⊗ q_target⁻¹), w = ω_bone, u = ω_pointer.
The coupling's rest is the pointer-to-bone relative pose at the moment of
gripping (``make_coupling``), so nothing jumps.  Each row's force is bounded by
±force_limit (N) or ±torque_limit (N·m).  The wrench the coupling puts on the
doll is Σ λ_k e_k; the user's hand feels its opposite.

Free mode: the pointer is a small kinematic sphere that collides with the bones
(contact rows whose static side moves with the pointer's velocity).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from solver import quat
from solver.model import Model
from solver.observe import points_on_bones
from solver.rows.compliance import voigt_row
from solver.rows.grip_kernel import segment_distances as distances
from solver.rows.table import KIND_GRIP, Rows, angular_jacobians, concat, make_rows, point_jacobians
from solver.state import State, StepInput


@dataclass(frozen=True)
class Pointer:
    """Pointer pose at the end of the step and its velocity over the step (world).

    pos (3,) m; quat (4,) (w,x,y,z); vel (3,) m/s; omega (3,) rad/s;
    radius (m): its contact sphere in free mode (0 = it touches nothing).
    """

    pos: np.ndarray
    quat: np.ndarray
    vel: np.ndarray
    omega: np.ndarray
    radius: float = 0.0


@dataclass(frozen=True)
class Coupling:
    """A grip: which bone, where, the rest relative pose, and the gains.

    body: body index; anchor (3,): grip point in the body frame (m);
    offset (3,): the same point in the pointer frame at gripping (m);
    rest (4,): bone orientation relative to the pointer at gripping;
    stiffness N/m, damping N·s/m, rot_stiffness N·m/rad, rot_damping N·m·s/rad;
    force_limit N, torque_limit N·m per row; position_only: no rotation rows.
    """

    body: int
    anchor: np.ndarray
    offset: np.ndarray
    rest: np.ndarray
    stiffness: float
    damping: float
    rot_stiffness: float
    rot_damping: float
    force_limit: float
    torque_limit: float
    position_only: bool = False


def make_coupling(
    state: State, pointer: Pointer, body: int, point_world: np.ndarray, **gains
) -> Coupling:
    """A coupling whose rest is the current pointer-to-bone pose (no jump at gripping)."""
    anchor = quat.rotate(quat.conj(state.body_quat[body]), point_world - state.body_pos[body])
    offset = quat.rotate(quat.conj(pointer.quat), point_world - pointer.pos)
    rest = quat.mul(quat.conj(pointer.quat), state.body_quat[body])
    return Coupling(body=body, anchor=anchor, offset=offset, rest=rest, **gains)


def coupling_vector(c: Coupling) -> np.ndarray:
    """The coupling as the compiled step's vector (solver.compiled.layout.Coupling: the
    fields of the same names, in order)."""
    gains = (c.stiffness, c.damping, c.rot_stiffness, c.rot_damping, c.force_limit,
             c.torque_limit)  # fmt: skip
    return np.concatenate((c.anchor, c.offset, c.rest, gains), dtype=np.float64)


def coupling_rows(state: State, pointer: Pointer, c: Coupling, h: float) -> Rows:
    """Translation rows (and rotation rows unless position-only) of a grip."""
    b = c.body
    r_b = quat.rotate(state.body_quat[b], c.anchor)
    target = pointer.pos + quat.rotate(pointer.quat, c.offset)
    u = pointer.vel + quat.cross(pointer.omega, target - pointer.pos)
    axes = np.eye(3)
    jac_a, jac_b = point_jacobians(axes, np.zeros((3, 3)), np.tile(r_b, (3, 1)))
    e = state.body_pos[b] + r_b - target
    comp, bias = voigt_row(c.stiffness, c.damping, e, h)
    blocks = [
        make_rows(KIND_GRIP, np.arange(3), -1, b, jac_a, jac_b, lo=-c.force_limit, hi=c.force_limit,
                  comp=comp, bias=bias - c.damping * u * comp)
    ]  # fmt: skip
    if not c.position_only:
        q_target = quat.mul(pointer.quat, c.rest)
        e_rot = quat.log(quat.mul(state.body_quat[b], quat.conj(q_target)))
        comp_r, bias_r = voigt_row(c.rot_stiffness, c.rot_damping, e_rot, h)
        bias_r = bias_r - c.rot_damping * pointer.omega * comp_r
        ja, jb = angular_jacobians(axes)
        blocks.append(
            make_rows(KIND_GRIP, np.arange(3, 6), -1, b, ja, jb, lo=-c.torque_limit,
                      hi=c.torque_limit, comp=comp_r, bias=bias_r)
        )  # fmt: skip
    return concat(blocks)


def coupling_wrench(rows: Rows, lam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(force (3,), torque (3,)) of the coupling on the bone; torque about the grip point."""
    sel = np.flatnonzero(rows.kind == KIND_GRIP)
    force, torque = np.zeros(3), np.zeros(3)
    for i in sel:
        slot = int(rows.key[i] & 0xF)
        if slot < 3:
            force[slot] = lam[i]
        else:
            torque[slot - 3] = lam[i]
    return force, torque


def segment_distances(model: Model, state: State, pos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(distance (nbone,), closest point (nbone,3)) from ``pos`` to each bone's head–tail axis."""
    nb = len(model.bone_names)
    rest = np.concatenate((model.bone_head0, model.bone_tail0))
    ends = points_on_bones(model, state.body_pos, state.body_quat, rest, np.tile(np.arange(nb), 2))
    head = ends[:nb]
    seg = ends[nb:] - head
    length2 = np.maximum(np.einsum("ni,ni->n", seg, seg), 1e-18)
    s = np.clip(np.einsum("ni,ni->n", pos - head, seg) / length2, 0.0, 1.0)
    closest = head + s[:, None] * seg
    return np.linalg.norm(closest - pos, axis=1), closest


def any_within(model: Model, state: State, pos: np.ndarray, gap: float) -> bool:
    """Some bone's head–tail axis is within ``gap`` of ``pos``: ``segment_distances``
    compiled (a run asks it every step while a released pointer clears the bones)."""
    dist = np.empty(len(model.bone_names))
    distances(state.body_pos, state.body_quat, model.body_pos0, model.bone_head0,
              model.bone_tail0, np.asarray(pos, dtype=float), dist)  # fmt: skip
    return bool(np.any(dist <= gap))


def nearest_point(
    model: Model, state: State, pos: np.ndarray, among: np.ndarray | None = None
) -> tuple[int, np.ndarray, float]:
    """(bone, closest point on its axis (world), distance) of the bone nearest to ``pos``.

    among (nbone,) bool: the bones to consider (None = all).  Distances are to the
    bones' axes, not their surfaces.
    """
    dist, closest = segment_distances(model, state, pos)
    if among is not None:
        dist = np.where(among, dist, np.inf)
    b = int(np.argmin(dist))
    return b, closest[b], float(dist[b])


def bone_reach(model: Model) -> np.ndarray:
    """(nbone,) how far each bone's shapes reach from its axis (m): radius or box half-diagonal."""
    g = model.geometry
    reach = np.zeros(len(model.bone_names))
    sel = (g.shape_body >= 0) & (g.shape_body < len(reach))
    size = np.where(
        g.shape_kind[sel] == 3, np.linalg.norm(g.shape_half[sel], axis=1), g.shape_radius[sel]
    )
    np.maximum.at(reach, g.shape_body[sel], size)
    return reach


def path_input(path: tuple, k: int, radius: float, coupling: Coupling | None) -> StepInput:
    """The input of step k along a pointer path (pos (n,3), quat (n,4): the pointer at
    each step's end; vel (n,3), omega (n,3): its mean velocities over each step), no loads."""
    pos, q, vel, omega = path
    return StepInput(None, None, Pointer(pos[k], q[k], vel[k], omega[k], radius), coupling)


def follow_steps(stepper, path: tuple, radius: float, coupling, wrench: np.ndarray) -> None:
    """A stepper's ``follow`` step by step: advance along ``path`` (``path_input``), each
    step's (grip force, grip torque, touch force) into wrench[k] (n, 9)."""
    for k in range(len(wrench)):
        stepper.advance(path_input(path, k, radius, coupling))
        stepper.wrench_into(wrench[k])
