"""Quantities read off a state: bone ends, joint rotations, energy, momentum, joint gaps."""

from __future__ import annotations

import numpy as np

from solver import quat
from solver.model import Model
from solver.state import State


def bone_points(
    model: Model, state: State, rest_points: np.ndarray, bones: np.ndarray | None = None
) -> np.ndarray:
    """World positions of points given in the rest pose, carried by bones.

    bones (k,): the bone of each point; None = one point per bone, in order.
    """
    return points_on_bones(model, state.body_pos, state.body_quat, rest_points, bones)


def points_on_bones(
    model: Model,
    body_pos: np.ndarray,
    body_quat: np.ndarray,
    rest_points: np.ndarray,
    bones: np.ndarray | None = None,
) -> np.ndarray:
    """``bone_points`` of body poses (..., nbody, 3) and (..., nbody, 4): any number of
    leading axes (a run's steps, say)."""
    b = np.arange(len(model.bone_names)) if bones is None else bones
    local = rest_points - model.body_pos0[b]
    return body_pos[..., b, :] + quat.rotate(body_quat[..., b, :], local)


def bone_heads(model: Model, state: State) -> np.ndarray:
    """World positions of the bones' heads (their joints), (nbone,3)."""
    return bone_points(model, state, model.bone_head0)


def bone_tails(model: Model, state: State) -> np.ndarray:
    """World positions of the bones' tails, (nbone,3)."""
    return bone_points(model, state, model.bone_tail0)


def relative_rotations(model: Model, body_quat: np.ndarray) -> np.ndarray:
    """q_rel = q_parent⁻¹ ⊗ q_child per joint, (..., nj, 4), of rotations (..., nbody, 4)."""
    world = np.broadcast_to(quat.IDENTITY, (*body_quat.shape[:-2], 1, 4))
    qs = np.concatenate((body_quat, world), axis=-2)
    return quat.mul(quat.conj(qs[..., model.joint_parent, :]), qs[..., model.joint_bone, :])


def joint_rotations(model: Model, state: State) -> np.ndarray:
    """Rotation vectors (nj,3) of the joints from their rest orientation, parent frame (rad)."""
    return quat.log(relative_rotations(model, state.body_quat))


def joint_gaps(model: Model, body_pos: np.ndarray, body_quat: np.ndarray) -> np.ndarray:
    """Distance (nj,) between each joint's two anchors (m)."""
    pos = np.vstack((body_pos, np.zeros((1, 3))))
    qs = np.vstack((body_quat, quat.IDENTITY))
    p, c = model.joint_parent, model.joint_bone
    a = pos[p] + quat.rotate(qs[p], model.joint_anchor_parent)
    b = pos[c] + quat.rotate(qs[c], model.joint_anchor_child)
    return np.linalg.norm(b - a, axis=1)


def kinetic_energy(model: Model, state: State) -> float:
    """Total kinetic energy (J) of the movable bodies."""
    rot = quat.matrix(state.body_quat)
    inertia_w = rot @ model.body_inertia @ np.swapaxes(rot, 1, 2)
    movable = model.body_inv_mass > 0.0
    lin = 0.5 * model.body_mass * np.einsum("ni,ni->n", state.body_vel, state.body_vel)
    ang = 0.5 * np.einsum("ni,nij,nj->n", state.body_omega, inertia_w, state.body_omega)
    return float(np.sum((lin + ang)[movable]))


def potential_energy(model: Model, state: State) -> float:
    """Gravitational potential energy (J) of the movable bodies, zero at the origin."""
    movable = model.body_inv_mass > 0.0
    return float(-np.sum((model.body_mass * (state.body_pos @ model.options.gravity))[movable]))


def momentum(model: Model, state: State) -> tuple[np.ndarray, np.ndarray]:
    """(linear (3,), angular about the origin (3,)) momentum of the movable bodies."""
    movable = (model.body_inv_mass > 0.0)[:, None]
    p = model.body_mass[:, None] * state.body_vel * movable
    rot = quat.matrix(state.body_quat)
    inertia_w = rot @ model.body_inertia @ np.swapaxes(rot, 1, 2)
    spin = np.einsum("nij,nj->ni", inertia_w, state.body_omega) * movable
    return p.sum(axis=0), (np.cross(state.body_pos, p) + spin).sum(axis=0)
