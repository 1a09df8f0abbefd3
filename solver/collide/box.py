"""Narrow phase for boxes against a plane and against spheres/capsules.

A box has centre c, rotation R (columns = its axes in world) and half extents h;
in box coordinates p = Rᵀ(x − c) its signed distance is

    q = |p| − h,   φ(p) = ‖max(q, 0)‖ + min(max_i q_i, 0),

with outward normal  sign(p)∘max(q, 0)/‖max(q, 0)‖  outside and  sign(p_k) e_k,
k = argmax q, inside (or on the surface).

plane–box (features 0..7 = corners, index bits = sign pattern of ``CORNERS``):
each corner x with depth −n·(x − p₀) ≥ −margin is a contact.

segment–box: f(t) = φ(p₀ + t·D), t ∈ [0, 1], is convex (φ is convex, the segment
affine) and piecewise smooth, so its minimum is at an end, a kink or a
stationary point of a smooth piece.  Outside, φ is C¹ (max(q, 0)² is), and its
pieces ‖(s_i p_i − h_i)_{i∈S}‖ are least at the closest points of the segment's
line to the 12 edge lines (|S| = 2) and the 8 corners (|S| = 3); |S| = 1 pieces
only reach their minimum, 0, where the segment touches a face.  Inside,
φ = max_i(|p_i| − h_i) is piecewise linear with kinks at p_i = 0 and at the
switches s_i p_i − h_i = s_j p_j − h_j (12).  Taking the least φ over these 37
candidates (with the two ends) is exact, with no iteration.  Contacts:
feature 0 the deepest point (kept only when it is not an end), features 1, 2 the
ends (so a capsule lying on a face has two), each with depth r − φ and the box
normal at that point of the axis; the normal points from the box to the segment.
"""

from __future__ import annotations

import itertools

import numpy as np

from solver.collide.segment import SAME_POINT, Found, dot, safe_div

CORNERS = np.array(list(itertools.product((-1.0, 1.0), repeat=3)))
"""(8, 3) corner sign patterns; corner k of a box is c + R (CORNERS[k] ∘ h)."""

# Pairs of box axes (i, j) with signs (s_i, s_j): edge lines and inside-max switches.
_I, _J, _SI, _SJ = (
    np.array(v)
    for v in zip(
        *[
            (i, j, si, sj)
            for i, j in ((0, 1), (0, 2), (1, 2))
            for si in (-1.0, 1.0)
            for sj in (-1.0, 1.0)
        ],
        strict=True,
    )
)


def box_sdf(p: np.ndarray, half: np.ndarray) -> np.ndarray:
    """Signed distance φ (...) of box-frame points p (..., 3) to boxes of half extents half."""
    q = np.abs(p) - half
    return np.linalg.norm(np.maximum(q, 0.0), axis=-1) + np.minimum(q.max(axis=-1), 0.0)


def box_normal(p: np.ndarray, half: np.ndarray) -> np.ndarray:
    """Outward unit normal (..., 3), box frame, of the box surface nearest to p."""
    q = np.abs(p) - half
    sign = np.where(p >= 0.0, 1.0, -1.0)
    out = np.maximum(q, 0.0)
    length = np.linalg.norm(out, axis=-1, keepdims=True)
    face = (q.argmax(axis=-1)[..., None] == np.arange(3)) * sign
    return np.where(length > 0.0, sign * out / np.maximum(length, 1e-300), face)


def deepest_param(p0: np.ndarray, dp: np.ndarray, half: np.ndarray) -> np.ndarray:
    """argmin over t ∈ [0,1] of φ(p0 + t·dp) (k,), box-frame segments p0 (k,3), dp (k,3)."""
    k = len(p0)
    centre_plane = safe_div(-p0, dp)
    hi, hj = half[:, _I], half[:, _J]
    pi, pj, di, dj = p0[:, _I], p0[:, _J], dp[:, _I], dp[:, _J]
    switch = safe_div(hi - hj - _SI * pi + _SJ * pj, _SI * di - _SJ * dj)
    edge = safe_div(-((pi - _SI * hi) * di + (pj - _SJ * hj) * dj), di * di + dj * dj)
    rel = p0[:, None, :] - CORNERS[None] * half[:, None, :]
    corner = safe_div(-dot(rel, dp[:, None, :]), dot(dp, dp)[:, None])
    ends = np.broadcast_to([0.0, 1.0], (k, 2))
    t = np.clip(np.concatenate((ends, centre_plane, switch, edge, corner), 1), 0.0, 1.0)
    phi = box_sdf(p0[:, None, :] + t[..., None] * dp[:, None, :], half[:, None, :])
    return t[np.arange(k), phi.argmin(axis=1)]


def segment_box(
    cb: np.ndarray,
    rot: np.ndarray,
    half: np.ndarray,
    c: np.ndarray,
    d: np.ndarray,
    lseg: np.ndarray,
    r: np.ndarray,
    margin: float,
) -> Found:
    """Box (centre cb, rotation rot, half extents) against segments c ± lseg·d of radius r."""
    p0 = np.einsum("kji,kj->ki", rot, c - lseg[:, None] * d - cb)
    dp = np.einsum("kji,kj->ki", rot, 2.0 * lseg[:, None] * d)
    t0 = deepest_param(p0, dp, half)
    t = np.stack((t0, np.zeros_like(t0), np.ones_like(t0)), axis=1)  # (k, 3)
    p = p0[:, None, :] + t[..., None] * dp[:, None, :]
    depth = r[:, None] - box_sdf(p, half[:, None, :])
    normal = np.einsum("kij,kfj->kfi", rot, box_normal(p, half[:, None, :]))
    x = cb[:, None, :] + np.einsum("kij,kfj->kfi", rot, p)
    point = x - normal * (r[:, None] - 0.5 * depth)[..., None]
    length = 2.0 * lseg
    keep = depth >= -margin
    keep[:, 0] &= (t0 * length > SAME_POINT) & ((1.0 - t0) * length > SAME_POINT)
    keep[:, 2] &= length > SAME_POINT
    return point, normal, depth, keep


def plane_box(
    p0: np.ndarray, n: np.ndarray, cb: np.ndarray, rot: np.ndarray, half: np.ndarray, margin: float
) -> Found:
    """Plane (point p0, normal n) against boxes: one contact per corner within margin."""
    x = cb[:, None, :] + np.einsum("kij,fj->kfi", rot * half[:, None, :], CORNERS)
    depth = -dot(x - p0[:, None, :], n[:, None, :])
    normal = np.broadcast_to(n[:, None, :], x.shape)
    point = x + normal * (0.5 * depth)[..., None]
    return point, normal, depth, depth >= -margin
