"""Small-vector and quaternion algebra for the compiled step, on tuples (no allocation).

Vectors are 3-tuples, quaternions 4-tuples (w, x, y, z), rotation matrices (n,3,3)
arrays read by index.  Every formula is ``solver.quat``'s, written in the same
floating-point order, so the compiled step agrees with the numpy step to rounding:

    a ⊗ b = (a_w b_w − a·b, a_w b + b_w a + a × b),   v' = v + w t + u × t,  t = 2 u × v,
    exp(θ) = (cos |θ|/2, sin(|θ|/2)/|θ| · θ),          log(q) = 2 atan2(|u|, w) u/|u|.
"""

from __future__ import annotations

import math

from solver.jit import kernel


@kernel(error_model="numpy")
def vec(a, i):
    """Row i of an (n,3) array as a 3-tuple."""
    return (a[i, 0], a[i, 1], a[i, 2])


@kernel(error_model="numpy")
def quat_at(a, i):
    """Row i of an (n,4) array as a 4-tuple."""
    return (a[i, 0], a[i, 1], a[i, 2], a[i, 3])


@kernel(error_model="numpy")
def vec_from(a, k):
    """a[k : k + 3] of a 1-D array as a 3-tuple."""
    return (a[k], a[k + 1], a[k + 2])


@kernel(error_model="numpy")
def quat_from(a, k):
    """a[k : k + 4] of a 1-D array as a 4-tuple."""
    return (a[k], a[k + 1], a[k + 2], a[k + 3])


@kernel(error_model="numpy")
def put(out, i, v):
    """out[i, :3] = v."""
    out[i, 0] = v[0]
    out[i, 1] = v[1]
    out[i, 2] = v[2]


@kernel(error_model="numpy")
def add(a, b):
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


@kernel(error_model="numpy")
def sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


@kernel(error_model="numpy")
def scale(s, a):
    return (s * a[0], s * a[1], s * a[2])


@kernel(error_model="numpy")
def neg(a):
    return (-a[0], -a[1], -a[2])


@kernel(error_model="numpy")
def dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@kernel(error_model="numpy")
def norm(a):
    return math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])


@kernel(error_model="numpy")
def cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


@kernel(error_model="numpy")
def clip(x, lo, hi):
    """np.clip for scalars (lo ≤ hi)."""
    return min(max(x, lo), hi)


@kernel(error_model="numpy")
def qmul(a, b):
    """Hamilton product a ⊗ b."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    )


@kernel(error_model="numpy")
def qconj(q):
    return (q[0], -q[1], -q[2], -q[3])


@kernel(error_model="numpy")
def qrotate(q, v):
    """Rotate v by the unit quaternion q."""
    u = (q[1], q[2], q[3])
    t = scale(2.0, cross(u, v))
    return add(add(v, scale(q[0], t)), cross(u, t))


EXP_SERIES = 0.05
"""θ/2 below which ``qexp`` takes the Taylor series (a step's rotation at h = 20 ms and
|ω| < 5 rad/s; at 1 ms, |ω| < 100 rad/s)."""


@kernel(error_model="numpy")
def qexp(v):
    """Unit quaternion of a rotation vector.  Below θ/2 = EXP_SERIES, cos(θ/2) and
    sin(θ/2)/θ are their Taylor series to x⁸: the first dropped terms (x¹⁰/10!,
    x¹⁰/(2·11!)) are < 3·10⁻²⁰, far below rounding, so these are the numbers sin and cos
    give, at a fraction of their cost."""
    angle = norm(v)
    half = 0.5 * angle
    if half < EXP_SERIES:
        x2 = half * half
        c = 1.0 - x2 * (0.5 - x2 * (1 / 24 - x2 * (1 / 720 - x2 * (1 / 40320))))
        k = 0.5 - x2 * (1 / 12 - x2 * (1 / 240 - x2 * (1 / 10080 - x2 * (1 / 725760))))
    else:
        c, k = math.cos(half), math.sin(half) / angle
    return (c, k * v[0], k * v[1], k * v[2])


LOG_SERIES = 0.03
"""tan(θ/4) below which ``qlog`` takes atan's series (θ ≈ 6.9°: a joint's elastic bend)."""


@kernel(error_model="numpy")
def qlog(q):
    """Rotation vector of a unit quaternion, shortest arc: (2 atan2(s, w)/s)·(x, y, z).
    Below x = s/w = LOG_SERIES, atan(x)/x is its series to x¹⁰ (the first dropped term,
    x¹²/13, is < 4·10⁻²⁰), so k = (2/w)·atan(x)/x without atan2; these are the numbers
    atan2 gives, to rounding."""
    if q[0] < 0.0:
        q = (-q[0], -q[1], -q[2], -q[3])
    s = math.sqrt(q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    if s < 1e-12:
        k = 2.0 / max(q[0], 1e-300)
    elif s < LOG_SERIES * q[0]:
        inv_w = 1.0 / q[0]
        x2 = (s * inv_w) * (s * inv_w)
        series = 1.0 - x2 * (1 / 3 - x2 * (1 / 5 - x2 * (1 / 7 - x2 * (1 / 9 - x2 * (1 / 11)))))
        k = 2.0 * inv_w * series
    else:
        k = 2.0 * math.atan2(s, q[0]) / s
    return (k * q[1], k * q[2], k * q[3])


@kernel(error_model="numpy")
def qnormalize(q):
    n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    return (q[0] / n, q[1] / n, q[2] / n, q[3] / n)


@kernel(error_model="numpy")
def qmatrix(q, out, i):
    """out[i] = rotation matrix of q (solver.quat.matrix)."""
    w, x, y, z = q
    out[i, 0, 0] = 1 - 2 * (y * y + z * z)
    out[i, 0, 1] = 2 * (x * y - w * z)
    out[i, 0, 2] = 2 * (x * z + w * y)
    out[i, 1, 0] = 2 * (x * y + w * z)
    out[i, 1, 1] = 1 - 2 * (x * x + z * z)
    out[i, 1, 2] = 2 * (y * z - w * x)
    out[i, 2, 0] = 2 * (x * z - w * y)
    out[i, 2, 1] = 2 * (y * z + w * x)
    out[i, 2, 2] = 1 - 2 * (x * x + y * y)


@kernel(error_model="numpy")
def matvec(m, i, v):
    """m[i] @ v for m (n,3,3)."""
    return (
        m[i, 0, 0] * v[0] + m[i, 0, 1] * v[1] + m[i, 0, 2] * v[2],
        m[i, 1, 0] * v[0] + m[i, 1, 1] * v[1] + m[i, 1, 2] * v[2],
        m[i, 2, 0] * v[0] + m[i, 2, 1] * v[1] + m[i, 2, 2] * v[2],
    )


@kernel(error_model="numpy")
def tmatvec(m, i, v):
    """m[i]ᵀ @ v for m (n,3,3)."""
    return (
        m[i, 0, 0] * v[0] + m[i, 1, 0] * v[1] + m[i, 2, 0] * v[2],
        m[i, 0, 1] * v[0] + m[i, 1, 1] * v[1] + m[i, 2, 1] * v[2],
        m[i, 0, 2] * v[0] + m[i, 1, 2] * v[1] + m[i, 2, 2] * v[2],
    )


@kernel(error_model="numpy")
def column(m, i, k):
    """Column k of m[i] (a body's axis k in world)."""
    return (m[i, 0, k], m[i, 1, k], m[i, 2, k])


@kernel(error_model="numpy")
def congruence(rot, i, inner, j, out, o):
    """out[o] = rot[i] @ inner[j] @ rot[i]ᵀ (world inertia or inverse inertia)."""
    for a in range(3):
        t0 = rot[i, a, 0] * inner[j, 0, 0] + rot[i, a, 1] * inner[j, 1, 0]
        t0 += rot[i, a, 2] * inner[j, 2, 0]
        t1 = rot[i, a, 0] * inner[j, 0, 1] + rot[i, a, 1] * inner[j, 1, 1]
        t1 += rot[i, a, 2] * inner[j, 2, 1]
        t2 = rot[i, a, 0] * inner[j, 0, 2] + rot[i, a, 1] * inner[j, 1, 2]
        t2 += rot[i, a, 2] * inner[j, 2, 2]
        for b in range(3):
            out[o, a, b] = t0 * rot[i, b, 0] + t1 * rot[i, b, 1] + t2 * rot[i, b, 2]


@kernel(error_model="numpy", _nrt=False)
def frames(quat, inertia, inv_inertia, rot, inertia_w, inv_i):
    """rot, inertia_w, inv_i (nb,3,3) ← each body's rotation R(q), world inertia R I Rᵀ
    and its inverse R I⁻¹ Rᵀ (inertia, inv_inertia: the bodies' own,
    m.body_inertia, m.body_inv_inertia)."""
    for b in range(len(quat)):
        qmatrix(quat_at(quat, b), rot, b)
        congruence(rot, b, inv_inertia, b, inv_i, b)
        congruence(rot, b, inertia, b, inertia_w, b)
