"""Compiled narrow phase for spheres and capsules (solver.collide.segment's twin):
against a plane and against each other, one pair at a time.
"""

from __future__ import annotations

from solver.jit import kernel
from solver.kin_kernel import add, clip, cross, dot, neg, norm, put, scale, sub

EPS = 1e-12


SAME_POINT = 1e-7


EARLY_OUT = 1e-6  # m: slack of the exact early-outs of segment_segment and segment_box


@kernel(error_model="numpy")
def emit(cb, n, ctx, feature, point, normal, depth):
    """Write contact n (normal already oriented first → second); returns n + 1."""
    body_a, body_b, friction, sign, key_base = ctx
    cb.body_a[n] = body_a
    cb.body_b[n] = body_b
    put(cb.point, n, point)
    put(cb.normal, n, scale(sign, normal))
    cb.depth[n] = depth
    cb.friction[n] = friction
    cb.key[n] = key_base + feature
    return n + 1


@kernel(error_model="numpy")
def safe_div(num, den):
    return num / den if abs(den) > EPS else 0.0


@kernel(error_model="numpy")
def _unit(v, n, fallback):
    if n > EPS:
        m = max(n, EPS)
        return (v[0] / m, v[1] / m, v[2] / m)
    return fallback


@kernel(error_model="numpy")
def any_perpendicular(d):
    pick = (1.0, 0.0, 0.0) if abs(d[0]) < 0.9 else (0.0, 1.0, 0.0)
    v = cross(d, pick)
    n = norm(v)
    return (v[0] / n, v[1] / n, v[2] / n)


@kernel(error_model="numpy")
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


@kernel(error_model="numpy")
def segment_params(p1, e1, p2, e2):
    """s, t ∈ [0, 1] of the closest points p1 + s·e1, p2 + t·e2 of two segments
    (solver.collide.segment.segment_params: Ericson §5.1.9, t from the first s)."""
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
    return s, clip(t, 0.0, 1.0)


@kernel(error_model="numpy")
def segment_segment(ca, da, la, ra, cb_, db, lb, rb, margin, ctx, cb, n):
    """Sphere/capsule a against sphere/capsule b: 0 closest points, 1–2 overlap ends.

    Feature 0 is the closest pair of points, so when even it is farther than the margin
    no feature can be kept and the pair is left before the other two are made.  The
    slack covers rounding and segment_params' near-parallel branch (sin²θ ≤ 10⁻¹²: s = 0,
    at most 2·la·θ ≤ 2·10⁻⁶·la from the closest point)."""
    pb = sub(cb_, scale(lb, db))
    eb = scale(2.0 * lb, db)
    s, _ = segment_params(sub(ca, scale(la, da)), scale(2.0 * la, da), pb, eb)
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


@kernel(error_model="numpy")
def _segment_distance(x, p, e):
    """Distance from point x to the segment p + t·e, t ∈ [0, 1] (as segment_segment's
    features measure it)."""
    t = clip(safe_div(dot(sub(x, p), e), dot(e, e)), 0.0, 1.0)
    return norm(sub(add(p, scale(t, e)), x))
