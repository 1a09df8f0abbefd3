"""One unit quaternion (w, x, y, z) as a tuple of Python floats: ``solver.quat``'s operations.

numpy spends ~20 µs on a ``quat.mul`` of one quaternion; a loop that handles one pose at a
time (a device tick, a pointer over one step) does it in Python floats instead.  Each
function performs the same floating-point operations in the same order as its
``solver.quat`` namesake, so the results are the same floats (tests/solver/test_quat1.py
compares them bit for bit).  The arc tangent is numpy's own (``np.arctan2`` of two floats,
~1 µs): on a CPU with AVX-512 numpy computes it with its own vector code, which differs
from libm's ``math.atan2`` in the last bit for about one argument in twelve.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["conj", "cross", "log", "mul", "normalize", "rotate"]

Quat = tuple[float, float, float, float]
Vec = tuple[float, float, float]


def mul(a: Quat, b: Quat) -> Quat:
    """Hamilton product a ⊗ b."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    )


def conj(q: Quat) -> Quat:
    """Conjugate (the inverse of a unit quaternion)."""
    return (q[0] * 1.0, q[1] * -1.0, q[2] * -1.0, q[3] * -1.0)


def cross(a: Vec, b: Vec) -> Vec:
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def rotate(q: Quat, v: Vec) -> Vec:
    """v rotated by q."""
    w, u = q[0], q[1:]
    t = tuple(2.0 * c for c in cross(u, v))
    c = cross(u, t)
    return (v[0] + w * t[0] + c[0], v[1] + w * t[1] + c[1], v[2] + w * t[2] + c[2])


def normalize(q: Quat) -> Quat:
    """q at unit length."""
    n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    return (q[0] / n, q[1] / n, q[2] / n, q[3] / n)


def log(q: Quat) -> Vec:
    """Rotation vector of q, shortest arc (angle ≤ π)."""
    if q[0] < 0.0:
        q = (-q[0], -q[1], -q[2], -q[3])
    s = math.sqrt(q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    k = 2.0 / max(q[0], 1e-300) if s < 1e-12 else 2.0 * float(np.arctan2(s, q[0])) / s
    return (k * q[1], k * q[2], k * q[3])
