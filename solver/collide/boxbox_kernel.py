"""Compiled box–box narrow phase (solver.collide.boxbox's twin, one pair at a time): the
separating-axis test, then the clipped face manifold or the edge contact, with the same
axes, preferences, features (0–15) and points as the numpy module's docstring gives.

The numpy module works on arrays of pairs; here one pair's quantities are scalars and
small tuples (4 incident vertices, 4 reference corners), so nothing is allocated."""

from __future__ import annotations

import math

from solver.collide.segment_kernel import emit, safe_div, segment_params
from solver.jit import kernel
from solver.kin_kernel import add, column, cross, dot, neg, norm, scale, sub, vec

AXIS_BIAS = 1e-3  # solver.collide.boxbox.AXIS_BIAS
CLIP_TOL = 1e-9  # solver.collide.boxbox._CLIP_TOL
QU = (1.0, -1.0, -1.0, 1.0)  # the incident face's vertices in cyclic order: signs along u
QV = (1.0, 1.0, -1.0, -1.0)  # and along v (solver.collide.boxbox._QUAD)


@kernel(error_model="numpy")
def _axis(rot, a, b, k):
    """Candidate axis k (unnormalised): 0–2 box a's axes, 3–5 box b's, 6–14 the cross
    product of a's axis (k − 6) // 3 with b's (k − 6) % 3."""
    if k < 3:
        return column(rot, a, k)
    if k < 6:
        return column(rot, b, k - 3)
    return cross(column(rot, a, (k - 6) // 3), column(rot, b, (k - 6) % 3))


@kernel(error_model="numpy")
def _reach(rot, s, half, axis):
    """Σ_i h_i |R_i · L|: box s's half extent along the unit axis L."""
    return (
        abs(dot(axis, column(rot, s, 0))) * half[s, 0]
        + abs(dot(axis, column(rot, s, 1))) * half[s, 1]
        + abs(dot(axis, column(rot, s, 2))) * half[s, 2]
    )


@kernel(error_model="numpy")
def _separation(offset, rot, half, a, b, k):
    """(sep, t, unit axis) of candidate axis k, offset = c_b − c_a (sep = −inf for a
    degenerate cross axis)."""
    raw = _axis(rot, a, b, k)
    length = norm(raw)
    unit = scale(1.0 / max(length, 1e-300), raw)
    t = dot(offset, unit)
    if length <= 1e-6:
        return -math.inf, t, unit
    return abs(t) - _reach(rot, a, half, unit) - _reach(rot, b, half, unit), t, unit


@kernel(error_model="numpy")
def _best_of(offset, rot, half, a, b, first, last):
    """The first axis of largest separation among candidates first … last − 1:
    (index, sep, t, unit axis)."""
    best = first
    sep, t, unit = _separation(offset, rot, half, a, b, first)
    for k in range(first + 1, last):
        s_k, t_k, u_k = _separation(offset, rot, half, a, b, k)
        if s_k > sep:
            best, sep, t, unit = k, s_k, t_k, u_k
    return best, sep, t, unit


@kernel(error_model="numpy")
def separating_axis(centre, rot, half, a, b):
    """(sep, axis index 0–14, unit axis a → b) of the pair's chosen axis: a's faces,
    then b's if better by the bias, then an edge axis if better than that by the bias."""
    bias = AXIS_BIAS * (half[a, 0] + half[a, 1] + half[a, 2] + half[b, 0] + half[b, 1]
                        + half[b, 2]) / 3.0  # fmt: skip
    offset = sub(vec(centre, b), vec(centre, a))
    best, sep, t, unit = _best_of(offset, rot, half, a, b, 0, 3)
    kb, sb, tb, ub = _best_of(offset, rot, half, a, b, 3, 6)
    if sb > sep + bias:
        best, sep, t, unit = kb, sb, tb, ub
    ke, se, te, ue = _best_of(offset, rot, half, a, b, 6, 15)
    if se > sep + bias:
        best, sep, t, unit = ke, se, te, ue
    return sep, best, (neg(unit) if t < 0.0 else unit)


@kernel(error_model="numpy")
def _incident_quad(n, centre, rot, half, i):
    """The 4 vertices (cyclic) and the outward normal of box i's face most opposed to n."""
    j, best = 0, -1.0
    for k in range(3):
        c = abs(dot(column(rot, i, k), n))
        if c > best:
            j, best = k, c
    cos = dot(column(rot, i, j), n)
    sign = 1.0 if cos > 0.0 else (-1.0 if cos < 0.0 else 0.0)
    m = scale(-sign, column(rot, i, j))
    ju, jv = (j + 1) % 3, (j + 2) % 3
    eu, ev = scale(half[i, ju], column(rot, i, ju)), scale(half[i, jv], column(rot, i, jv))
    mid = add(vec(centre, i), scale(half[i, j], m))
    w = (
        add(add(mid, scale(QU[0], eu)), scale(QV[0], ev)),
        add(add(mid, scale(QU[1], eu)), scale(QV[1], ev)),
        add(add(mid, scale(QU[2], eu)), scale(QV[2], ev)),
        add(add(mid, scale(QU[3], eu)), scale(QV[3], ev)),
    )
    return w, m


@kernel(error_model="numpy")
def _clip_edge(x0, y0, x1, y1, hu, hv):
    """Liang–Barsky on the incident edge (x0, y0) → (x1, y1) against the reference
    rectangle: (enter, leave, enter kept, leave kept)."""
    dx, dy = x1 - x0, y1 - y0
    p = (-dx, dx, -dy, dy)
    q = (x0 + hu, hu - x0, y0 + hv, hv - y0)
    enter, leave, outside = 0.0, 1.0, False
    for k in range(4):
        ratio = safe_div(q[k], p[k])
        if p[k] < 0.0:
            enter = max(enter, ratio)
        elif p[k] > 0.0:
            leave = min(leave, ratio)
        outside = outside or (abs(p[k]) <= 1e-12 and q[k] < -CLIP_TOL)
    tol = safe_div(10.0 * CLIP_TOL, math.hypot(dx, dy))
    valid = not outside and enter <= leave
    return enter, leave, valid and enter > tol, valid and leave < 1.0 - tol


@kernel(error_model="numpy")
def _corner_inside(cx, cy, x, y):
    """Whether the reference corner (cx, cy) lies strictly inside the incident quad."""
    pos, neg_ = True, True
    for q in range(4):
        ex, ey = x[(q + 1) % 4] - x[q], y[(q + 1) % 4] - y[q]
        side = safe_div(ex * (cy - y[q]) - ey * (cx - x[q]), math.hypot(ex, ey))
        pos = pos and side > CLIP_TOL
        neg_ = neg_ and side < -CLIP_TOL
    return pos or neg_


@kernel(error_model="numpy")
def _face_contacts(frame, w, m, normal, margin, ctx, cb, n):
    """The face manifold's features (module docstring of solver.collide.boxbox) with
    depth ≥ −margin, each point moved half its depth along the reference normal; when none
    is kept, the incident vertex deepest along it alone.  Returns the new count."""
    nrm, fc, fu, fv, hu, hv = frame
    x = (dot(sub(w[0], fc), fu), dot(sub(w[1], fc), fu), dot(sub(w[2], fc), fu),
         dot(sub(w[3], fc), fu))  # fmt: skip
    y = (dot(sub(w[0], fc), fv), dot(sub(w[1], fc), fv), dot(sub(w[2], fc), fv),
         dot(sub(w[3], fc), fv))  # fmt: skip
    z = (dot(sub(w[0], fc), nrm), dot(sub(w[1], fc), nrm), dot(sub(w[2], fc), nrm),
         dot(sub(w[3], fc), nrm))  # fmt: skip
    start = n
    for q in range(4):  # features 0–3: incident vertices inside the rectangle
        inside = abs(x[q]) <= hu + CLIP_TOL and abs(y[q]) <= hv + CLIP_TOL
        if inside and -z[q] >= -margin:
            n = emit(cb, n, ctx, q, add(w[q], scale(-0.5 * z[q], nrm)), normal, -z[q])
    mu, mv, mn = dot(m, fu), dot(m, fv), dot(m, nrm)
    for c in range(4):  # features 4–7: reference corners inside the incident quad
        cx, cy = QU[c] * hu, QV[c] * hv
        zc = safe_div(dot(m, sub(w[0], fc)) - cx * mu - cy * mv, mn)
        if _corner_inside(cx, cy, x, y) and -zc >= -margin:
            pc = add(add(add(fc, scale(cx, fu)), scale(cy, fv)), scale(zc, nrm))
            n = emit(cb, n, ctx, 4 + c, add(pc, scale(-0.5 * zc, nrm)), normal, -zc)
    for q in range(4):  # features 8–15: incident edges entering / leaving the rectangle
        e = (q + 1) % 4
        enter, leave, enter_ok, leave_ok = _clip_edge(x[q], y[q], x[e], y[e], hu, hv)
        for f, t, ok in ((8 + 2 * q, enter, enter_ok), (9 + 2 * q, leave, leave_ok)):
            ze = z[q] + t * (z[e] - z[q])
            if ok and -ze >= -margin:
                pe = add(w[q], scale(t, sub(w[e], w[q])))
                n = emit(cb, n, ctx, f, add(pe, scale(-0.5 * ze, nrm)), normal, -ze)
    if n == start:  # the faces' projections miss each other: the deepest incident vertex
        q = 0
        for k in range(1, 4):
            if -z[k] > -z[q]:
                q = k
        n = emit(cb, n, ctx, q, add(w[q], scale(-0.5 * z[q], nrm)), normal, -z[q])
    return n


@kernel(error_model="numpy")
def _edge_point(centre, rot, half, a, b, best, axis):
    """Midway between the closest points of a's supporting edge (extreme along the axis)
    and b's (extreme against it)."""
    ia, ib = (best - 6) // 3, (best - 6) % 3
    pa, ea = _support_edge(centre, rot, half, a, ia, axis)
    pb, eb = _support_edge(centre, rot, half, b, ib, neg(axis))
    s, t = segment_params(pa, ea, pb, eb)
    return scale(0.5, add(add(pa, scale(s, ea)), add(pb, scale(t, eb))))


@kernel(error_model="numpy")
def _support_edge(centre, rot, half, s, i, towards):
    """(start, direction) of box s's edge along its axis i farthest along ``towards``."""
    start = vec(centre, s)
    for k in range(3):
        sign = 1.0 if dot(column(rot, s, k), towards) >= 0.0 else -1.0
        if k == i:
            sign = -1.0
        start = add(start, scale(sign * half[s, k], column(rot, s, k)))
    return start, scale(2.0 * half[s, i], column(rot, s, i))


@kernel(error_model="numpy")
def box_box(centre, rot, half, a, b, margin, ctx, cb, n):
    """Box a against box b (world centres, rotations and half extents of shapes a, b):
    up to 8 contacts, normals a → b before ctx's sign; returns the new count."""
    sep, best, axis = separating_axis(centre, rot, half, a, b)
    if sep > margin:
        return n
    if best >= 6:
        point = _edge_point(centre, rot, half, a, b, best, axis)
        return emit(cb, n, ctx, 0, point, axis, -sep)
    on_b = best >= 3
    i = best % 3
    ref, inc = (b, a) if on_b else (a, b)
    nrm = neg(axis) if on_b else axis  # outward from the reference box
    iu, iv = (i + 1) % 3, (i + 2) % 3
    fc = add(vec(centre, ref), scale(half[ref, i], nrm))
    frame = (nrm, fc, column(rot, ref, iu), column(rot, ref, iv), half[ref, iu], half[ref, iv])
    w, m = _incident_quad(nrm, centre, rot, half, inc)
    return _face_contacts(frame, w, m, axis, margin, ctx, cb, n)
