"""Ball-joint rows: anchor (position) rows, rheology rows and swing/twist limit rows.

Frames.  R_p is the parent's world rotation (identity for the world), q_rel =
q_p⁻¹ ⊗ q_c the child's orientation in the parent frame; at rest q_rel = 1, so the
joint rotation is log(q_rel), a rotation vector in the parent frame.

Anchor rows (3 per joint, world axes e_k):  C = p_c − p_p (the two anchors).
Both bodies are pushed at the common point p_m = (p_p + p_c)/2, so every joint
impulse is a pure force pair through one point and momentum is conserved
exactly.  w_k = e_k·(v_c + ω_c × r_c − v_p − ω_p × r_p).
A rotating anchor moves on an arc, not along ω × r: over the step it moves by
h ω × r + N with N = exp(hω) r − r − h ω × r (second order in hω).  Without N the
anchors drift apart by O((hω)²r) every step.  So the row asks
C[t+1] ≈ C + h w + N_c − N_p = (1 − erp) C:
    bias = (erp·C + N_c − N_p)/h.

Rheology rows (3 per joint, the parent's axes a_k = R_p e_k):
w_k = a_k·(ω_c − ω_p).  Flowing joints use the three-element row on q_sf,
elastic ones the Voigt row on δ = log(q_rel ⊗ q_anchor⁻¹) (see solver.rows.compliance).

Limit rows (one-sided, only while within ``limit_margin`` of a limit).  With d
the bone axis at rest and d' = q_rel d:
  swing  θ = acos(d·d'),  C = swing − θ ≥ 0,  dθ/dt = n·ω_rel, n = d × d'/|d × d'|;
  twist  φ = 2·atan2(q_rel.xyz·d, q_rel.w),  C = φ − lo ≥ 0 and hi − φ ≥ 0,
         dφ/dt = R_p (d + d')/(1 + d·d') · ω_rel  (q_rel = swing ⊗ twist, the twist about
         d; exact at any swing, tests/solver/test_jacobians.py; the denominator is kept
         above TWIST_FLOOR, a swing within 2.6° of π, where the twist is undefined).
A row with C > 0 is speculative: bias C/h lets the joint reach the limit in one
step but not pass it; a violated row pulls back with erp·C/h.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from solver import quat
from solver.model import Model
from solver.rows.compliance import three_element_row, voigt_row
from solver.rows.table import (
    KIND_JOINT,
    KIND_LIMIT,
    KIND_RHEOLOGY,
    Rows,
    angular_jacobians,
    make_rows,
    point_jacobians,
)
from solver.state import State


@dataclass(frozen=True)
class JointFrames:
    """World quantities of every joint at the current pose.

    anchor_parent, anchor_child (nj,3) m; rot_parent (nj,3,3); q_rel (nj,4);
    com_parent, com_child (nj,3) m (the world's "centre" is the origin).
    """

    anchor_parent: np.ndarray
    anchor_child: np.ndarray
    rot_parent: np.ndarray
    q_rel: np.ndarray
    com_parent: np.ndarray
    com_child: np.ndarray


def joint_frames(
    model: Model, body_pos: np.ndarray, body_quat: np.ndarray, body_rot: np.ndarray
) -> JointFrames:
    """Joint frames; index -1 (the world) reads the identity pose appended at the end."""
    pos = np.vstack((body_pos, np.zeros((1, 3))))
    qs = np.vstack((body_quat, quat.IDENTITY))
    rot = np.concatenate((body_rot, np.eye(3)[None]), axis=0)
    p, c = model.joint_parent, model.joint_bone
    rot_p = rot[p]
    anchor_p = pos[p] + np.einsum("nij,nj->ni", rot_p, model.joint_anchor_parent)
    anchor_c = pos[c] + np.einsum("nij,nj->ni", rot[c], model.joint_anchor_child)
    q_rel = quat.mul(quat.conj(qs[p]), qs[c])
    return JointFrames(anchor_p, anchor_c, rot_p, q_rel, pos[p], pos[c])


def arc_offset(omega: np.ndarray, r: np.ndarray, h: float) -> np.ndarray:
    """N = exp(hω) r − r − h ω × r: the part of an anchor's motion a linear row misses."""
    return quat.rotate(quat.exp(h * omega), r) - r - h * quat.cross(omega, r)


def anchor_rows(model: Model, fr: JointFrames, h: float, omega: np.ndarray | None = None) -> Rows:
    """Three hard rows per joint keeping its two anchors together.

    omega (nb,3): angular velocities for the arc correction (None: no correction): the
    last step's solved ones, not the unconstrained free velocities, which carry a
    large external torque's whole effect before the joints share it.
    """
    nj = model.njoint
    gap = model.options.joint_erp * (fr.anchor_child - fr.anchor_parent)
    if omega is not None:
        w = np.vstack((omega, np.zeros((1, 3))))
        gap += arc_offset(w[model.joint_bone], fr.anchor_child - fr.com_child, h)
        gap -= arc_offset(w[model.joint_parent], fr.anchor_parent - fr.com_parent, h)
    mid = 0.5 * (fr.anchor_parent + fr.anchor_child)
    axes = np.tile(np.eye(3), (nj, 1))
    r_a = np.repeat(mid - fr.com_parent, 3, axis=0)
    r_b = np.repeat(mid - fr.com_child, 3, axis=0)
    jac_a, jac_b = point_jacobians(axes, r_a, r_b)
    return make_rows(
        KIND_JOINT,
        np.arange(3 * nj),
        np.repeat(model.joint_parent, 3),
        np.repeat(model.joint_bone, 3),
        jac_a,
        jac_b,
        bias=gap.reshape(-1) / h,
    )


def flowing(model: Model, yielded: np.ndarray) -> np.ndarray:
    """(nj,) bool: joints whose rheology row is the three-element (flowing) one.

    A joint flows when it has a finite series damper and has either yielded or
    has no yield torque at all; otherwise it is a Voigt spring about its anchor.
    """
    plastic = np.all(np.isfinite(model.joint_dd), axis=1)
    return plastic & (yielded | ~np.isfinite(model.joint_yield))


def elastic_deflection(q_rel: np.ndarray, anchor: np.ndarray) -> np.ndarray:
    """δ = log(q_rel ⊗ anchor⁻¹): the deflection from the elastic rest, parent frame."""
    return quat.log(quat.mul(q_rel, quat.conj(anchor)))


def rheology_rows(model: Model, state: State, fr: JointFrames, h: float) -> tuple[Rows, np.ndarray]:
    """Three compliant rows per joint with rheology; returns (rows, joint index per row)."""
    j = np.flatnonzero(model.joint_rheology)
    kf, df, dd = model.joint_kf[j], model.joint_df[j], model.joint_dd[j]
    flow = flowing(model, state.joint_yielded)[j][:, None]
    delta = elastic_deflection(fr.q_rel[j], state.joint_anchor[j])
    c_v, b_v = voigt_row(kf, df, delta, h)
    safe_dd = np.where(np.isfinite(dd), dd, 1.0)
    c_p, b_p = three_element_row(kf, df, safe_dd, state.joint_q_sf[j], h)
    comp = np.where(flow, c_p, c_v).reshape(-1)
    bias = np.where(flow, b_p, b_v).reshape(-1)
    axes = np.swapaxes(fr.rot_parent[j], 1, 2).reshape(-1, 3)  # rows of Rᵀ = columns of R
    jac_a, jac_b = angular_jacobians(axes)
    rows = make_rows(
        KIND_RHEOLOGY,
        np.repeat(3 * j, 3) + np.tile(np.arange(3), len(j)),
        np.repeat(model.joint_parent[j], 3),
        np.repeat(model.joint_bone[j], 3),
        jac_a,
        jac_b,
        comp=comp,
        bias=bias,
    )
    return rows, np.repeat(j, 3)


TWIST_FLOOR = 1e-3
"""Least 1 + d·d' in the twist rows' axis (d + d')/(1 + d·d'): a swing within 2.6° of π."""


def _limit_candidates(model: Model, fr: JointFrames) -> tuple[list, list, list, list]:
    """(joint, slot, world axis, C) for every limit within its margin."""
    d = model.joint_axis
    d_now = quat.rotate(fr.q_rel, d)
    cos_s = np.clip(np.einsum("ni,ni->n", d, d_now), -1.0, 1.0)
    swing_c = model.joint_swing - np.arccos(cos_s)
    q = np.where(fr.q_rel[:, :1] < 0.0, -fr.q_rel, fr.q_rel)
    twist = 2.0 * np.arctan2(np.einsum("ni,ni->n", q[:, 1:], d), q[:, 0])
    twist = (twist + np.pi) % (2.0 * np.pi) - np.pi
    rate = (d + d_now) / np.maximum(1.0 + cos_s, TWIST_FLOOR)[:, None]
    twist_axis = np.einsum("nij,nj->ni", fr.rot_parent, rate)
    margin = model.options.limit_margin
    out = ([], [], [], [])
    for j in np.flatnonzero(swing_c < margin):
        n = quat.cross(d[j], d_now[j])
        norm = np.linalg.norm(n)
        n = n / norm if norm > 1e-9 else _perpendicular(d[j])
        _append(out, j, 0, -(fr.rot_parent[j] @ n), swing_c[j])
    for j in np.flatnonzero(twist - model.joint_twist_lo < margin):
        _append(out, j, 1, twist_axis[j], twist[j] - model.joint_twist_lo[j])
    for j in np.flatnonzero(model.joint_twist_hi - twist < margin):
        _append(out, j, 2, -twist_axis[j], model.joint_twist_hi[j] - twist[j])
    return out


def _append(out: tuple, j: int, slot: int, axis: np.ndarray, c: float) -> None:
    for lst, value in zip(out, (j, slot, axis, c), strict=True):
        lst.append(value)


def _perpendicular(d: np.ndarray) -> np.ndarray:
    n = quat.cross(d, [1.0, 0.0, 0.0])
    if np.linalg.norm(n) < 1e-6:
        n = quat.cross(d, [0.0, 0.0, 1.0])
    return n / np.linalg.norm(n)


def limit_rows(model: Model, fr: JointFrames, h: float) -> Rows:
    """One-sided rows for the swing cone and twist range limits near or past their bound."""
    joints, slots, axes, c = _limit_candidates(model, fr)
    joints = np.array(joints, dtype=np.int64)
    c = np.array(c, dtype=float)
    axes = np.array(axes, dtype=float).reshape(-1, 3)
    jac_a, jac_b = angular_jacobians(axes)
    erp = model.options.joint_erp
    return make_rows(
        KIND_LIMIT,
        4 * joints + np.array(slots, dtype=np.int64),
        model.joint_parent[joints],
        model.joint_bone[joints],
        jac_a,
        jac_b,
        lo=0.0,
        bias=np.where(c >= 0.0, c, erp * c) / h,
    )
