"""Compiled narrow phase: plane/sphere/capsule/box pairs (not box–box), one pair at a time.

The geometry and conventions are ``solver.collide``'s (see its docstring and those of
``collide_segment`` and ``collide_box``): a sphere or capsule is the set of points within
r of the segment c + u·d, u ∈ [−l, l]; a box has centre c, rotation R, half extents h and
the signed distance φ(p) = ‖max(|p| − h, 0)‖ + min(maxᵢ(|pᵢ| − hᵢ), 0) in box
coordinates p = Rᵀ(x − c).  Normals point from the first shape to the second, depth > 0
is overlap, a contact is kept when depth ≥ −margin, the point is midway between the
surfaces.  Each kernel writes its kept features, in feature order, through ``emit``
into the contact buffers cb = (body_a, body_b, point, normal, depth, friction, key)
and returns the new contact count; ``ctx`` = (body_a, body_b, friction, sign, key base)
with sign = −1 when the pair was swapped so that normals run from a to b.
"""

from __future__ import annotations

import math

from numba import njit

from solver.fast.kin import add, clip, cross, dot, matvec, neg, norm, put, scale, sub, tmatvec

EPS = 1e-12
SAME_POINT = 1e-7
EARLY_OUT = 1e-6  # m: slack of the exact early-outs of segment_segment and segment_box


@njit(cache=True, error_model="numpy")
def emit(cb, n, ctx, feature, point, normal, depth):
    """Write contact n (normal already oriented first → second); returns n + 1."""
    body_a, body_b, friction, sign, key_base = ctx
    cb[0][n] = body_a
    cb[1][n] = body_b
    put(cb[2], n, point)
    put(cb[3], n, scale(sign, normal))
    cb[4][n] = depth
    cb[5][n] = friction
    cb[6][n] = key_base + feature
    return n + 1


@njit(cache=True, error_model="numpy")
def safe_div(num, den):
    return num / den if abs(den) > EPS else 0.0


@njit(cache=True, error_model="numpy")
def _unit(v, n, fallback):
    if n > EPS:
        m = max(n, EPS)
        return (v[0] / m, v[1] / m, v[2] / m)
    return fallback


@njit(cache=True, error_model="numpy")
def any_perpendicular(d):
    pick = (1.0, 0.0, 0.0) if abs(d[0]) < 0.9 else (0.0, 1.0, 0.0)
    v = cross(d, pick)
    n = norm(v)
    return (v[0] / n, v[1] / n, v[2] / n)


@njit(cache=True, error_model="numpy")
def plane_segment(p0, nrm, c, d, half, r, margin, ctx, cb, n):
    """Plane (p0, normal nrm) against the segment c ± half·d of radius r: features = ends."""
    for f in range(2):
        u = -half if f == 0 else half
        x = add(c, scale(u, d))
        depth = r - dot(sub(x, p0), nrm)
        point = sub(x, scale(r - 0.5 * depth, nrm))
        if depth >= -margin and (f == 0 or half > SAME_POINT):
            n = emit(cb, n, ctx, f, point, nrm, depth)
    return n


@njit(cache=True, error_model="numpy")
def _corner_offset(rot, s, i, half, sx, sy, sz):
    """Component i of R (corner signs ∘ h), summed as einsum does."""
    return rot[s, i, 0] * half[0] * sx + rot[s, i, 1] * half[1] * sy + rot[s, i, 2] * half[2] * sz


@njit(cache=True, error_model="numpy")
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


@njit(cache=True, error_model="numpy")
def segment_param(p1, e1, p2, e2):
    """s ∈ [0, 1] of the closest point p1 + s·e1 to segment p2 + t·e2 (Ericson §5.1.9)."""
    r = sub(p1, p2)
    a, e, b = dot(e1, e1), dot(e2, e2), dot(e1, e2)
    c, f = dot(e1, r), dot(e2, r)
    denom = a * e - b * b
    s = clip(safe_div(b * f - c * e, denom), 0.0, 1.0) if denom > 1e-12 * a * e else 0.0
    t = safe_div(b * s + f, e)
    if t < 0.0 or e <= EPS:
        s = clip(safe_div(-c, a), 0.0, 1.0)
    elif t > 1.0:
        s = clip(safe_div(b - c, a), 0.0, 1.0)
    return s


@njit(cache=True, error_model="numpy")
def segment_segment(ca, da, la, ra, cb_, db, lb, rb, margin, ctx, cb, n):
    """Sphere/capsule a against sphere/capsule b: 0 closest points, 1–2 overlap ends.

    Feature 0 is the closest pair of points, so when even it is farther than the margin
    no feature can be kept and the pair is left before the other two are made.  The
    slack covers rounding and segment_param's near-parallel branch (sin²θ ≤ 10⁻¹²: s = 0,
    at most 2·la·θ ≤ 2·10⁻⁶·la from the closest point)."""
    pb = sub(cb_, scale(lb, db))
    eb = scale(2.0 * lb, db)
    s = segment_param(sub(ca, scale(la, da)), scale(2.0 * la, da), pb, eb)
    u0 = (2.0 * s - 1.0) * la
    slack = EARLY_OUT * (1.0 + 2.0 * (la + lb))
    if _segment_distance(add(ca, scale(u0, da)), pb, eb) - (ra + rb) > margin + slack:
        return n
    mid, spread = dot(sub(cb_, ca), da), lb * abs(dot(db, da))
    lo = clip(mid - spread, -la, la)
    hi = clip(mid + spread, -la, la)
    towards = sub(cb_, ca)
    fb = _unit(cross(da, db), norm(cross(da, db)), any_perpendicular(da))
    if dot(fb, towards) < 0.0:
        fb = neg(fb)
    ebb = dot(eb, eb)
    for f in range(3):
        u = u0 if f == 0 else (lo if f == 1 else hi)
        xa = add(ca, scale(u, da))
        t = clip(safe_div(dot(sub(xa, pb), eb), ebb), 0.0, 1.0)
        v = sub(add(pb, scale(t, eb)), xa)
        length = norm(v)
        normal = _unit(v, length, fb)
        depth = (ra + rb) - length
        point = add(xa, scale(ra - 0.5 * depth, normal))
        keep = depth >= -margin
        if f == 2:
            keep = keep and hi - lo > SAME_POINT
        elif f == 0:
            keep = keep and abs(u0 - lo) > SAME_POINT and abs(u0 - hi) > SAME_POINT
        if keep:
            n = emit(cb, n, ctx, f, point, normal, depth)
    return n


@njit(cache=True, error_model="numpy")
def _segment_distance(x, p, e):
    """Distance from point x to the segment p + t·e, t ∈ [0, 1] (as segment_segment's
    features measure it)."""
    t = clip(safe_div(dot(sub(x, p), e), dot(e, e)), 0.0, 1.0)
    return norm(sub(add(p, scale(t, e)), x))


@njit(cache=True, error_model="numpy")
def box_sdf(p, half):
    q0, q1, q2 = abs(p[0]) - half[0], abs(p[1]) - half[1], abs(p[2]) - half[2]
    m0, m1, m2 = max(q0, 0.0), max(q1, 0.0), max(q2, 0.0)
    return math.sqrt(m0 * m0 + m1 * m1 + m2 * m2) + min(max(q0, q1, q2), 0.0)


@njit(cache=True, error_model="numpy")
def box_normal(p, half):
    """Outward unit normal (box frame) of the box surface nearest to p."""
    q = (abs(p[0]) - half[0], abs(p[1]) - half[1], abs(p[2]) - half[2])
    sign = (
        1.0 if p[0] >= 0.0 else -1.0,
        1.0 if p[1] >= 0.0 else -1.0,
        1.0 if p[2] >= 0.0 else -1.0,
    )
    out = (max(q[0], 0.0), max(q[1], 0.0), max(q[2], 0.0))
    length = norm(out)
    if length > 0.0:
        m = max(length, 1e-300)
        return (sign[0] * out[0] / m, sign[1] * out[1] / m, sign[2] * out[2] / m)
    k = 0
    if q[1] > q[k]:
        k = 1
    if q[2] > q[k]:
        k = 2
    return (sign[0] if k == 0 else 0.0, sign[1] if k == 1 else 0.0, sign[2] if k == 2 else 0.0)


_AXIS_I = (0, 0, 0, 0, 0, 0, 0, 0, 1, 1, 1, 1)
_AXIS_J = (1, 1, 1, 1, 2, 2, 2, 2, 2, 2, 2, 2)


@njit(cache=True, error_model="numpy")
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


@njit(cache=True, error_model="numpy")
def deepest_param(p0, dp, half):
    """argmin over t ∈ [0,1] of φ(p0 + t·dp), exact over the 37 candidates (first minimum)."""
    best_t, best_phi = 0.0, math.inf
    for c in range(37):
        t = clip(_candidate(c, p0, dp, half), 0.0, 1.0)
        phi = box_sdf(add(p0, scale(t, dp)), half)
        if phi < best_phi:
            best_t, best_phi = t, phi
    return best_t


@njit(cache=True, error_model="numpy")
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
