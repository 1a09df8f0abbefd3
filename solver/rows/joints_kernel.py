"""Compiled ball-joint rows (solver.rows.joints's twin): anchor, rheology and limit rows,
the same rows in the same order.
"""

from __future__ import annotations

import math

import numpy as np

from solver.compiled.layout import Limits
from solver.jit import kernel
from solver.kin_kernel import (
    add,
    clip,
    column,
    cross,
    dot,
    matvec,
    neg,
    norm,
    qconj,
    qexp,
    qlog,
    qmul,
    qrotate,
    quat_at,
    scale,
    sub,
    vec,
)
from solver.rows.joints import TWIST_FLOOR
from solver.rows.table import KIND_JOINT, KIND_LIMIT, KIND_RHEOLOGY
from solver.rows.table_kernel import AXES, INF, ZERO, angular_jac, null_rows, point_jac, set_row


@kernel(error_model="numpy")
def arc_offset(omega, r, h):
    """N = exp(hω) r − r − h ω × r: the part of an anchor's motion a linear row misses."""
    return sub(sub(qrotate(qexp(scale(h, omega)), r), r), scale(h, cross(omega, r)))


@kernel(error_model="numpy", _nrt=False)
def anchor_rows(joints, pos, rot, omega, h, erp, arc, asleep, rw, n):
    """Three hard rows per joint (anchors pushed at their midpoint), bias (erp·C + N_c − N_p)/h.

    rot (nb,3,3) body rotations; omega (nb,3) the angular velocities of the arc terms
    (the last step's solved ones, as solver.pipeline); arc=False drops the arc terms (the
    projection's rows); asleep (nb,) bool: joints of sleeping bodies get empty rows."""
    parent, bone, anc_p, anc_c = (
        joints  # m.joint_parent, m.joint_bone, m.joint_anchor_parent, m.joint_anchor_child
    )
    for j in range(len(parent)):
        p, c = parent[j], bone[j]
        if asleep[c]:
            n = null_rows(rw, n, KIND_JOINT, j, 3)
            continue
        com_p = vec(pos, p) if p >= 0 else ZERO
        arm_p = matvec(rot, p, vec(anc_p, j)) if p >= 0 else vec(anc_p, j)
        a_p = add(com_p, arm_p)
        com_c = vec(pos, c)
        a_c = add(com_c, matvec(rot, c, vec(anc_c, j)))
        gap = scale(erp, sub(a_c, a_p))
        if arc:
            gap = add(gap, arc_offset(_omega(omega, c), sub(a_c, com_c), h))
            gap = sub(gap, arc_offset(_omega(omega, p), sub(a_p, com_p), h))
        mid = scale(0.5, add(a_p, a_c))
        r_a, r_b = sub(mid, com_p), sub(mid, com_c)
        for k in range(3):
            ja, jb = point_jac(AXES[k], r_a, r_b)
            set_row(rw, n, KIND_JOINT, 3 * j + k, p, c, ja, jb, -INF, INF, 0.0, gap[k] / h, -1, 0.0)
            n += 1
    return n


@kernel(error_model="numpy")
def _omega(omega, b):
    return vec(omega, b) if b >= 0 else ZERO


@kernel(error_model="numpy", inline="always")
def q_rel(j, parent, bone, quat):
    """q_p⁻¹ ⊗ q_c of joint j (the world's q_p is the identity).  Inlined, as
    ``flowing``: three arrays, three uses per joint a step."""
    p = parent[j]
    qp = quat_at(quat, p) if p >= 0 else (1.0, 0.0, 0.0, 0.0)
    return qmul(qconj(qp), quat_at(quat, bone[j]))


@kernel(error_model="numpy", inline="always")
def flowing(plastic, finite_yield, yielded, j):
    """Joint j uses the three-element row: finite D_d and yielded (or no yield torque).

    (Helpers called per joint or per row take single arrays, never the packed tuples:
    passing a tuple of many arrays to a call costs far more than the call's work where
    references are counted.  This one is inlined: called from counted code, each of its
    three arrays cost two reference-count calls, three times per joint a step; most of
    the step runs uncounted now, kernel._step.)"""
    return plastic[j] and (yielded[j] or not finite_yield[j])


@kernel(error_model="numpy", _nrt=False)
def rheology_rows(rheo, quat, rot, h, q_sf, yielded, anchor, asleep, rheo_joint, rw, n):
    """Three compliant rows per joint with rheology, on the parent's axes a_k = R_p e_k:
    Voigt C = 1/(D_f + K_f h), bias K_f δ/(D_f + K_f h), δ = log(q_rel ⊗ anchor⁻¹);
    three-element C = (D_d + D_f + K_f h)/(D_d (K_f h + D_f)), bias K_f q_sf/(K_f h + D_f)."""
    parent, bone, kf, df, dd, has, _, plastic, finite_yield = rheo  # post.rheology_update's
    for j in range(len(parent)):
        if not has[j]:
            continue
        if asleep[bone[j]]:
            for k in range(3):
                rheo_joint[n + k] = j
            n = null_rows(rw, n, KIND_RHEOLOGY, j, 3)
            continue
        p = parent[j]
        delta = qlog(qmul(q_rel(j, parent, bone, quat), qconj(quat_at(anchor, j))))
        flow = flowing(plastic, finite_yield, yielded, j)
        for k in range(3):
            if flow:
                s = kf[j, k] * h + df[j, k]
                comp = (dd[j, k] + df[j, k] + kf[j, k] * h) / (dd[j, k] * s)
                bias = kf[j, k] / s * q_sf[j, k]
            else:
                s = df[j, k] + kf[j, k] * h
                comp, bias = 1.0 / s, kf[j, k] * delta[k] / s
            axis = column(rot, p, k) if p >= 0 else AXES[k]
            ja, jb = angular_jac(axis)
            set_row(
                rw, n, KIND_RHEOLOGY, 3 * j + k, p, bone[j], ja, jb, -INF, INF, comp, bias, -1, 0.0
            )
            rheo_joint[n] = j
            n += 1
    return n


@kernel(error_model="numpy")
def _perpendicular(d):
    v = cross(d, (1.0, 0.0, 0.0))
    if norm(v) < 1e-6:
        v = cross(d, (0.0, 0.0, 1.0))
    return _div(v, norm(v))


@kernel(error_model="numpy")
def _div(v, s):
    return (v[0] / s, v[1] / s, v[2] / s)


@kernel(error_model="numpy")
def _wrap(x):
    """(x + π) mod 2π − π (numba's float % is Python's, i.e. numpy's, floor mod)."""
    return (x + math.pi) % (2.0 * math.pi) - math.pi


@kernel(error_model="numpy", inline="always")
def limit_arrays(m):
    """What ``limit_rows`` reads of the model (layout.Limits): joint parents, bones, rest
    axes, swing and twist limits, thresholds."""
    return Limits(
        m.joint_parent,
        m.joint_bone,
        m.joint_axis,
        m.joint_swing,
        m.joint_twist_lo,
        m.joint_twist_hi,
        m.joint_limit_thresholds,
    )


@kernel(error_model="numpy", _nrt=False)
def limit_rows(limits, quat, rot, h, erp, margin, asleep, rw, n, gaps, turned):
    """One-sided rows (λ ≥ 0) for limits within ``margin``: swing rows of every joint,
    then twist-low, then twist-high; bias C/h when C ≥ 0 (speculative) else erp·C/h.
    swing θ = acos(d·d'), C = swing − θ, axis −R_p (d × d')/|d × d'|;
    twist φ = 2 atan2(q.xyz·d, q.w) wrapped to [−π, π), C = φ − lo or hi − φ, axis
    ±R_p (d + d')/max(1 + d·d', TWIST_FLOOR).
    Joints of sleeping bodies (asleep) have none.  Each joint's C and d' are computed
    once (``limit_gaps``, into the scratch arrays gaps and turned (nj, 3)), the rows
    then made in their order."""
    parent, bone, axis_rest = limits.parent, limits.bone, limits.axis
    limit_gaps(limits, quat, asleep, gaps, turned)
    for slot in range(3):
        for j in range(len(parent)):
            c = gaps[j, slot]
            if asleep[bone[j]] or not c < margin:
                continue
            p = parent[j]
            d, d_now = vec(axis_rest, j), vec(turned, j)
            if slot == 0:
                nv = cross(d, d_now)
                length = norm(nv)
                nv = _div(nv, length) if length > 1e-9 else _perpendicular(d)
                world = neg(matvec(rot, p, nv) if p >= 0 else nv)
            else:
                rate = scale(1.0 / max(1.0 + dot(d, d_now), TWIST_FLOOR), add(d, d_now))
                world = matvec(rot, p, rate) if p >= 0 else rate
                world = world if slot == 1 else neg(world)
            ja, jb = angular_jac(world)
            bias = (c if c >= 0.0 else erp * c) / h
            set_row(
                rw, n, KIND_LIMIT, 4 * j + slot, p, bone[j], ja, jb, 0.0, INF, 0.0, bias, -1, 0.0
            )
            n += 1
    return n


@kernel(error_model="numpy", inline="always")
def limit_gaps(limits, quat, asleep, gaps, turned):
    """gaps (nj, 3) ← C of the swing, twist-low and twist-high limits, turned (nj, 3) ←
    d' = q_rel d, of every awake joint (``limit_rows``).  A C that cannot be below the margin is +∞,
    its angle not computed: a joint well inside its limits by the thresholds
    (``limit_thresholds``: an infinite limit is never reached), which compare d·d' and
    the twist's tangent without acos or atan2 and keep a 10⁻⁹ rad margin over the
    rounding of either, so the rows made are exactly those the angles give."""
    parent, bone, axis_rest, swing, tw_lo, tw_hi, thresholds = limits  # limit_arrays
    nj = len(parent)
    for j in range(nj):
        if asleep[bone[j]]:
            continue
        q = q_rel(j, parent, bone, quat)
        d = vec(axis_rest, j)
        d_now = qrotate(q, d)
        for k in range(3):
            turned[j, k] = d_now[k]
        cos_swing = clip(dot(d, d_now), -1.0, 1.0)
        gaps[j, 0] = INF
        if not cos_swing >= thresholds[j, 0]:
            gaps[j, 0] = swing[j] - math.acos(cos_swing)
        if q[0] < 0.0:
            q = (-q[0], -q[1], -q[2], -q[3])
        along, w = q[1] * d[0] + q[2] * d[1] + q[3] * d[2], q[0]
        gaps[j, 1] = gaps[j, 2] = INF
        inside = w > 0.0 and along >= w * thresholds[j, 1] and along <= w * thresholds[j, 2]
        if not inside:
            twist = _wrap(2.0 * math.atan2(along, w))
            gaps[j, 1], gaps[j, 2] = twist - tw_lo[j], tw_hi[j] - twist


LIMIT_SLACK = 1e-9


"""rad: how far inside (margin included) a limit must be for ``limit_thresholds`` to
skip its angle: far above the rounding of acos, atan2 and the products compared."""


def limit_thresholds(swing, twist_lo, twist_hi, margin: float) -> np.ndarray:
    """(nj, 3) for ``limit_gaps``: cos(swing − margin − slack), below which d·d' must
    fall for a swing row to be possible (2: always possible; −2: never), and the
    tangents of half the twist range's inner bounds (lo + margin + slack)/2 and
    (hi − margin − slack)/2: with q_w > 0 the twist is 2 atan(s/q_w), so
    q_w tan_lo ≤ s ≤ q_w tan_hi means neither twist row.  An infinite bound gets −∞ /
    +∞ (never reached); a finite half-angle within 10⁻⁶ of ±π/2 (where the twist wraps
    at ±π) gets +∞ / −∞: no skip, the angle decides."""
    a = swing - margin - LIMIT_SLACK
    cos_swing = np.where(a <= 0.0, 2.0, np.where(a >= np.pi, -2.0, np.cos(np.clip(a, 0, np.pi))))
    half_lo = 0.5 * (twist_lo + margin + LIMIT_SLACK)
    half_hi = 0.5 * (twist_hi - margin - LIMIT_SLACK)
    edge = 0.5 * np.pi - 1e-6
    with np.errstate(invalid="ignore"):
        tan_lo = np.where(np.abs(half_lo) < edge, np.tan(np.clip(half_lo, -edge, edge)), np.inf)
        tan_hi = np.where(np.abs(half_hi) < edge, np.tan(np.clip(half_hi, -edge, edge)), -np.inf)
    tan_lo[twist_lo == -np.inf], tan_hi[twist_hi == np.inf] = -np.inf, np.inf
    return np.stack((cos_swing, tan_lo, tan_hi), axis=1)
