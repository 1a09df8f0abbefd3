"""Compiled narrow phase for boxes against a plane and against spheres/capsules
(solver.collide.box's twin; box–box pairs: solver.collide.boxbox_kernel).
"""

from __future__ import annotations

import math

from solver.collide.segment_kernel import EARLY_OUT, SAME_POINT, emit, safe_div
from solver.jit import kernel
from solver.kin_kernel import add, clip, dot, matvec, neg, norm, scale, sub, tmatvec


@kernel(error_model="numpy")
def _corner_offset(rot, s, i, half, sx, sy, sz):
    """Component i of R (corner signs ∘ h), summed as einsum does."""
    return rot[s, i, 0] * half[0] * sx + rot[s, i, 1] * half[1] * sy + rot[s, i, 2] * half[2] * sz


@kernel(error_model="numpy")
def plane_box(p0, nrm, centre, rot, s, half, margin, ctx, cb, n):
    """Plane against box s (centre, rot[s], half): one contact per corner within margin."""
    for f in range(8):
        sx = 1.0 if f & 4 else -1.0
        sy = 1.0 if f & 2 else -1.0
        sz = 1.0 if f & 1 else -1.0
        xv = (
            centre[0] + _corner_offset(rot, s, 0, half, sx, sy, sz),
            centre[1] + _corner_offset(rot, s, 1, half, sx, sy, sz),
            centre[2] + _corner_offset(rot, s, 2, half, sx, sy, sz),
        )
        depth = -dot(sub(xv, p0), nrm)
        if depth >= -margin:
            n = emit(cb, n, ctx, f, add(xv, scale(0.5 * depth, nrm)), nrm, depth)
    return n


@kernel(error_model="numpy")
def box_sdf(p, half):
    q0, q1, q2 = abs(p[0]) - half[0], abs(p[1]) - half[1], abs(p[2]) - half[2]
    m0, m1, m2 = max(q0, 0.0), max(q1, 0.0), max(q2, 0.0)
    return math.sqrt(m0 * m0 + m1 * m1 + m2 * m2) + min(max(q0, q1, q2), 0.0)


@kernel(error_model="numpy")
def box_normal(p, half):
    """Outward unit normal (box frame) of the box surface nearest to p."""
    q = (abs(p[0]) - half[0], abs(p[1]) - half[1], abs(p[2]) - half[2])
    sign = (
        1.0 if p[0] >= 0.0 else -1.0,
        1.0 if p[1] >= 0.0 else -1.0,
        1.0 if p[2] >= 0.0 else -1.0,
    )
    outside = (max(q[0], 0.0), max(q[1], 0.0), max(q[2], 0.0))
    length = norm(outside)
    if length > 0.0:
        m = max(length, 1e-300)
        return (sign[0] * outside[0] / m, sign[1] * outside[1] / m, sign[2] * outside[2] / m)
    k = 0
    if q[1] > q[k]:
        k = 1
    if q[2] > q[k]:
        k = 2
    return (sign[0] if k == 0 else 0.0, sign[1] if k == 1 else 0.0, sign[2] if k == 2 else 0.0)


_AXIS_I = (0, 0, 0, 0, 0, 0, 0, 0, 1, 1, 1, 1)


_AXIS_J = (1, 1, 1, 1, 2, 2, 2, 2, 2, 2, 2, 2)


@kernel(error_model="numpy")
def _candidate(c, p0, dp, half):
    """Candidate c (0–36) of ``collide_box.deepest_param``: ends, centre planes, switches,
    edges, corners, in that order."""
    if c < 2:
        return float(c)
    if c < 5:
        return safe_div(-p0[c - 2], dp[c - 2])
    if c < 29:
        k = (c - 5) % 12
        i, j = _AXIS_I[k], _AXIS_J[k]
        si = 1.0 if k & 2 else -1.0
        sj = 1.0 if k & 1 else -1.0
        hi, hj, pi, pj, di, dj = half[i], half[j], p0[i], p0[j], dp[i], dp[j]
        if c < 17:
            return safe_div(hi - hj - si * pi + sj * pj, si * di - sj * dj)
        return safe_div(-((pi - si * hi) * di + (pj - sj * hj) * dj), di * di + dj * dj)
    f = c - 29
    rel = (
        p0[0] - (1.0 if f & 4 else -1.0) * half[0],
        p0[1] - (1.0 if f & 2 else -1.0) * half[1],
        p0[2] - (1.0 if f & 1 else -1.0) * half[2],
    )
    return safe_div(-dot(rel, dp), dot(dp, dp))


@kernel(error_model="numpy")
def deepest_param(p0, dp, half):
    """argmin over t ∈ [0,1] of φ(p0 + t·dp), exact over the 37 candidates (first minimum)."""
    best_t, best_phi = 0.0, math.inf
    for c in range(37):
        t = clip(_candidate(c, p0, dp, half), 0.0, 1.0)
        phi = box_sdf(add(p0, scale(t, dp)), half)
        if phi < best_phi:
            best_t, best_phi = t, phi
    return best_t


@kernel(error_model="numpy")
def segment_box(cbox, rot, s, half, c, d, lseg, r, margin, ctx, cb, n):
    """Segment c ± lseg·d of radius r (first) against box s: 0 deepest point, 1–2 ends.

    The box's distance φ is 1-Lipschitz and every point of the segment is within lseg of
    its middle, so φ ≥ φ(middle) − lseg along it: when that bound is farther than the
    margin (by more than EARLY_OUT) no feature can be kept, and the 37-candidate search
    is skipped."""
    if box_sdf(tmatvec(rot, s, sub(c, cbox)), half) - lseg - r > margin + EARLY_OUT:
        return n
    p0 = tmatvec(rot, s, sub(sub(c, scale(lseg, d)), cbox))
    dp = tmatvec(rot, s, scale(2.0 * lseg, d))
    t0 = deepest_param(p0, dp, half)
    length = 2.0 * lseg
    for f in range(3):
        t = t0 if f == 0 else float(f - 1)
        p = add(p0, scale(t, dp))
        depth = r - box_sdf(p, half)
        normal = matvec(rot, s, box_normal(p, half))
        x = add(cbox, matvec(rot, s, p))
        point = sub(x, scale(r - 0.5 * depth, normal))
        keep = depth >= -margin
        if f == 0:
            keep = keep and t0 * length > SAME_POINT and (1.0 - t0) * length > SAME_POINT
        elif f == 2:
            keep = keep and length > SAME_POINT
        if keep:
            n = emit(cb, n, ctx, f, point, neg(normal), depth)
    return n
