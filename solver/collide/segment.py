"""Narrow phase for spheres and capsules: against a plane and against each other.

A sphere or capsule is every point within radius r of the segment
x(u) = c + u·d, u ∈ [−l, l] (d unit, l = 0 for a sphere), all in world coordinates.

Every kernel here (and in ``collide_box``/``collide_boxbox``) returns a ``Found``
tuple ``(point (k,F,3), normal (k,F,3), depth (k,F), keep (k,F))`` for k pairs
(first, second): column f holds the contact of geometric feature f, ``normal``
points from the first shape to the second, ``depth`` > 0 is overlap and only
columns with ``keep`` are contacts.  ``point`` is midway between the surfaces.

plane–segment (features 0, 1 = ends u = −l, +l): the gap of end x_e is
    g_e = n·(x_e − p₀) − r,  depth −g_e.
The gap is linear in u, so its minimum is at an end, and both ends together
support a capsule lying flat.

segment–segment: the closest points x_a, x_b of the two segments (Ericson,
*Real-Time Collision Detection* §5.1.9, parallel-safe) give
    depth = r_a + r_b − |x_b − x_a|,  normal = (x_b − x_a)/|x_b − x_a|.
The distance from x_a(u) to segment b is convex in u, so contacts at the two ends
[u_lo, u_hi] of b's projection onto a's axis (clipped to a's extent), each paired
with the closest point of b, are valid support points too: they give a capsule
resting parallel on another two contacts (features 1, 2).  The closest-point
contact (feature 0) is kept only when it is a different point of a.
"""

from __future__ import annotations

import numpy as np

Found = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]
"""(point (k,F,3), normal (k,F,3), depth (k,F), keep (k,F) bool); column f = feature f."""

EPS = 1e-12
SAME_POINT = 1e-7
"""m: two contacts of one pair closer than this along a segment are the same feature."""


def dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Dot product over the last axis."""
    return np.einsum("...i,...i->...", a, b)


def safe_div(num: np.ndarray, den: np.ndarray) -> np.ndarray:
    """num/den, and 0 where |den| ≤ EPS (callers clamp or mask such entries)."""
    ok = np.abs(den) > EPS
    return np.where(ok, num / np.where(ok, den, 1.0), 0.0)


def unit(v: np.ndarray, fallback: np.ndarray) -> np.ndarray:
    """v/|v| over the last axis, or the (unit) fallback where |v| ≤ EPS."""
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return np.where(n > EPS, v / np.maximum(n, EPS), fallback)


def any_perpendicular(d: np.ndarray) -> np.ndarray:
    """Unit vectors (..., 3) perpendicular to unit vectors d (..., 3)."""
    # Cross with a world axis at least ~25° away from d, so the product never vanishes.
    pick = np.where(np.abs(d[..., :1]) < 0.9, [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    v = np.cross(d, pick)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def segment_params(
    p1: np.ndarray, e1: np.ndarray, p2: np.ndarray, e2: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """s, t ∈ [0, 1] of the closest points p1 + s·e1, p2 + t·e2 of two segments (k,3).

    Ericson §5.1.9; parallel or zero-length segments get one valid closest pair.
    """
    r = p1 - p2
    a, e, b = dot(e1, e1), dot(e2, e2), dot(e1, e2)
    c, f = dot(e1, r), dot(e2, r)
    denom = a * e - b * b
    s = np.where(denom > 1e-12 * a * e, np.clip(safe_div(b * f - c * e, denom), 0.0, 1.0), 0.0)
    t = safe_div(b * s + f, e)
    s = np.where(
        (t < 0.0) | (e <= EPS),
        np.clip(safe_div(-c, a), 0.0, 1.0),
        np.where(t > 1.0, np.clip(safe_div(b - c, a), 0.0, 1.0), s),
    )
    return s, np.clip(t, 0.0, 1.0)


def plane_segment(
    p0: np.ndarray,
    n: np.ndarray,
    c: np.ndarray,
    d: np.ndarray,
    half: np.ndarray,
    r: np.ndarray,
    margin: float,
) -> Found:
    """Plane (point p0, normal n) against segments c ± half·d of radius r: features = ends."""
    u = np.stack((-half, half), axis=1)  # (k, 2)
    x = c[:, None, :] + u[..., None] * d[:, None, :]
    depth = r[:, None] - dot(x - p0[:, None, :], n[:, None, :])
    normal = np.broadcast_to(n[:, None, :], x.shape)
    point = x - normal * (r[:, None] - 0.5 * depth)[..., None]
    keep = depth >= -margin
    keep[:, 1] &= half > SAME_POINT  # a sphere's two "ends" are one point
    return point, normal, depth, keep


def _fallback_normal(da: np.ndarray, db: np.ndarray, towards: np.ndarray) -> np.ndarray:
    """Normal for touching axes (distance 0): perpendicular to both, facing ``towards``."""
    n = unit(np.cross(da, db), any_perpendicular(da))
    return np.where(dot(n, towards)[:, None] < 0.0, -n, n)


def segment_segment(
    ca: np.ndarray,
    da: np.ndarray,
    la: np.ndarray,
    ra: np.ndarray,
    cb: np.ndarray,
    db: np.ndarray,
    lb: np.ndarray,
    rb: np.ndarray,
    margin: float,
) -> Found:
    """Sphere/capsule a against sphere/capsule b: features 0 closest, 1–2 overlap ends."""
    pb, eb = cb - lb[:, None] * db, 2.0 * lb[:, None] * db
    s, _ = segment_params(ca - la[:, None] * da, 2.0 * la[:, None] * da, pb, eb)
    u0 = (2.0 * s - 1.0) * la
    # b's projection onto a's axis, clipped to a's extent.
    mid, spread = dot(cb - ca, da), lb * np.abs(dot(db, da))
    lo = np.clip(mid - spread, -la, la)
    hi = np.clip(mid + spread, -la, la)
    u = np.stack((u0, lo, hi), axis=1)  # (k, 3)
    xa = ca[:, None, :] + u[..., None] * da[:, None, :]
    t = np.clip(safe_div(dot(xa - pb[:, None, :], eb[:, None, :]), dot(eb, eb)[:, None]), 0, 1)
    v = pb[:, None, :] + t[..., None] * eb[:, None, :] - xa
    fallback = _fallback_normal(da, db, cb - ca)[:, None, :]
    normal = unit(v, fallback)
    depth = (ra + rb)[:, None] - np.linalg.norm(v, axis=-1)
    point = xa + normal * (ra[:, None] - 0.5 * depth)[..., None]
    keep = depth >= -margin
    keep[:, 2] &= hi - lo > SAME_POINT
    keep[:, 0] &= (np.abs(u0 - lo) > SAME_POINT) & (np.abs(u0 - hi) > SAME_POINT)
    return point, normal, depth, keep
