"""Vectorised unit-quaternion algebra, (w, x, y, z), on arrays of shape (..., 4).

Rotation of a vector: v' = q ⊗ (0, v) ⊗ q*.  ``exp``/``log`` map between a
rotation vector θ·n (rad) and the unit quaternion (cos θ/2, sin θ/2 · n); ``log``
returns the shortest rotation (angle in [0, π]).
"""

from __future__ import annotations

import numpy as np


def mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product a ⊗ b."""
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack(
        (
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ),
        axis=-1,
    )


def conj(q: np.ndarray) -> np.ndarray:
    """Conjugate (the inverse of a unit quaternion)."""
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a × b over the last axis (broadcasting); np.cross's generality costs ~10× here."""
    a, b = np.broadcast_arrays(a, b)
    out = np.empty(a.shape)
    out[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    out[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    out[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return out


def rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vectors v (..., 3) by unit quaternions q (..., 4)."""
    w = q[..., :1]
    u = q[..., 1:]
    t = 2.0 * cross(u, v)
    return v + w * t + cross(u, t)


def matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of unit quaternions."""
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack(
        (
            np.stack((1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)), -1),
            np.stack((2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)), -1),
            np.stack((2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)), -1),
        ),
        axis=-2,
    )


def exp(rotvec: np.ndarray) -> np.ndarray:
    """Unit quaternion of a rotation vector (..., 3), exact for all angles."""
    angle = np.linalg.norm(rotvec, axis=-1, keepdims=True)
    half = 0.5 * angle
    # sin(θ/2)/θ, with its Taylor series near 0 so tiny rotations stay exact.
    small = angle < 1e-8
    safe = np.where(small, 1.0, angle)
    k = np.where(small, 0.5 - angle * angle / 48.0, np.sin(half) / safe)
    return np.concatenate((np.cos(half), k * rotvec), axis=-1)


def log(q: np.ndarray) -> np.ndarray:
    """Rotation vector (..., 3) of unit quaternions, shortest arc (angle ≤ π)."""
    q = np.where(q[..., :1] < 0.0, -q, q)
    s = np.linalg.norm(q[..., 1:], axis=-1, keepdims=True)
    angle = 2.0 * np.arctan2(s, q[..., :1])
    small = s < 1e-12
    k = np.where(small, 2.0 / np.maximum(q[..., :1], 1e-300), angle / np.where(small, 1.0, s))
    return k * q[..., 1:]


def normalize(q: np.ndarray) -> np.ndarray:
    """Renormalise to unit length."""
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


OPPOSITE = 1.5e-8
"""|a + b| (unit a, b) below which ``from_two_vectors`` takes the two as opposite: there
the shortest arc's axis a × b, of length ~|a + b|, carries a rounding error of
~1e-16/|a + b| rad, and taking any axis ⟂ a instead errs by at most |a + b|; the two
are equal near 1.5e-8."""


def from_two_vectors(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Shortest-arc unit quaternion rotating direction a onto direction b (both (3,)): b
    within ~2e-16/|a + b| rad (unit a, b); for opposite directions (|a + b| < OPPOSITE) a
    half turn about an axis ⟂ a, a × x̂ (or a × ẑ when a is along x)."""
    a = a / np.linalg.norm(a)
    b = b / np.linalg.norm(b)
    c = float(np.dot(a, b))
    half = a + b
    if np.linalg.norm(half) < OPPOSITE:
        axis = np.cross(a, [1.0, 0.0, 0.0])
        if np.linalg.norm(axis) < 1e-6:
            axis = np.cross(a, [0.0, 0.0, 1.0])
        axis /= np.linalg.norm(axis)
        return np.array([0.0, *axis])
    # 1 + c = |a + b|²/2, which keeps its digits where a·b is near −1 and 1 + c has none
    w = 1.0 + c if c > -0.5 else 0.5 * float(np.dot(half, half))
    q = np.array([w, *np.cross(a, b)])
    return q / np.linalg.norm(q)


IDENTITY = np.array([1.0, 0.0, 0.0, 0.0])
