"""Box–box narrow phase: separating-axis test and a clipped face manifold.

Separating axes (Gottschalk's OBB test): the 3 face axes of a, the 3 of b and the 9
cross products of an a-edge with a b-edge.  Along a unit axis L, with
T = c_b − c_a,

    sep(L) = |T·L| − Σ_i h_a,i |A_i·L| − Σ_i h_b,i |B_i·L|,

is a lower bound on the gap (> 0 separated).  The axis of largest sep gives the
contact normal (oriented a → b) and depth −sep; a face axis is preferred unless
an edge axis beats it by ``AXIS_BIAS`` times the boxes' size, and a's faces over
b's, so the choice does not flicker between near-equal axes.  Nothing is
reported when max sep > margin.

Face contact: the chosen face is the reference face (centre f, outward normal n,
in-plane axes u, v with half sizes h_u, h_v); the incident face is the face of the
other box whose outward normal is most opposed to n.  In reference coordinates
(x, y, z) = ((w − f)·u, (w − f)·v, (w − f)·n), the manifold is the set of vertices of
the intersection of the reference rectangle with the incident quad, each at its
height z on the incident face, depth −z:

    features 0–3    incident vertices inside the rectangle,
    features 4–7    reference corners strictly inside the incident quad,
    features 8–15   incident edge q entering (8 + 2q) / leaving (9 + 2q) the
                    rectangle (Liang–Barsky clipping of the edge).

A convex quad and a rectangle intersect in at most 8 vertices, so at most 8 of
these are kept; only those with depth ≥ −margin are.  The normal points from a
to b (negated when the reference face is b's).  When the projections of the two
faces miss each other (boxes apart diagonally, within the margin), the incident
vertex deepest along n (gap = sep) is kept alone, so no speculative contact is lost.

Edge contact: the supporting edges of a (extreme along +L) and of b (along −L);
one contact (feature 0) midway between their closest points, depth −sep.
"""

from __future__ import annotations

import numpy as np

from solver.collide.segment import Found, dot, safe_div, segment_params

AXIS_BIAS = 1e-3
"""Relative tolerance favouring face axes over edge axes and a's faces over b's."""
_CLIP_TOL = 1e-9
"""m: slack of the inside tests, so coincident edges produce no duplicate points."""
# Incident face vertices in cyclic order, as signs along its two in-plane axes.
_QUAD = np.array([[1.0, 1.0], [-1.0, 1.0], [-1.0, -1.0], [1.0, -1.0]])


def separating_axis(
    ca: np.ndarray, ra: np.ndarray, ha: np.ndarray, cb: np.ndarray, rb: np.ndarray, hb: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Best axis per pair: (sep (k,), axis index 0..14 (k,), unit axis a → b (k,3))."""
    k = len(ca)
    ax_a, ax_b = ra.transpose(0, 2, 1), rb.transpose(0, 2, 1)  # rows = box axes
    cross = np.cross(ax_a[:, :, None, :], ax_b[:, None, :, :]).reshape(k, 9, 3)
    axes = np.concatenate((ax_a, ax_b, cross), axis=1)
    length = np.linalg.norm(axes, axis=-1)
    axes = axes / np.maximum(length, 1e-300)[..., None]
    t = dot((cb - ca)[:, None, :], axes)  # (k,1,3) against (k,15,3)
    reach_a = np.einsum("kli,ki->kl", np.abs(np.einsum("kla,kia->kli", axes, ax_a)), ha)
    reach_b = np.einsum("kli,ki->kl", np.abs(np.einsum("kla,kia->kli", axes, ax_b)), hb)
    sep = np.where(length > 1e-6, np.abs(t) - reach_a - reach_b, -np.inf)
    bias = AXIS_BIAS * (ha.sum(axis=1) + hb.sum(axis=1)) / 3.0
    best = sep[:, :3].argmax(axis=1)
    face_b = sep[:, 3:6].argmax(axis=1) + 3
    rows = np.arange(k)
    best = np.where(sep[rows, face_b] > sep[rows, best] + bias, face_b, best)
    edge = sep[:, 6:].argmax(axis=1) + 6
    best = np.where(sep[rows, edge] > sep[rows, best] + bias, edge, best)
    axis = axes[rows, best]
    axis = np.where(t[rows, best][:, None] < 0.0, -axis, axis)
    return sep[rows, best], best, axis


def _incident_quad(n: np.ndarray, ci: np.ndarray, ri: np.ndarray, hi: np.ndarray):
    """Vertices (k,4,3) and outward normal (k,3) of the face of box i most opposed to n."""
    rows = np.arange(len(n))
    cos = np.einsum("kij,ki->kj", ri, n)
    j = np.abs(cos).argmax(axis=1)
    m = -np.sign(cos[rows, j])[:, None] * ri[rows, :, j]
    ju, jv = (j + 1) % 3, (j + 2) % 3
    eu = ri[rows, :, ju] * hi[rows, ju][:, None]
    ev = ri[rows, :, jv] * hi[rows, jv][:, None]
    centre = ci + m * hi[rows, j][:, None]
    w = centre[:, None, :] + _QUAD[None, :, :1] * eu[:, None] + _QUAD[None, :, 1:] * ev[:, None]
    return w, m


def _clip_edges(x: np.ndarray, y: np.ndarray, hu: np.ndarray, hv: np.ndarray):
    """Liang–Barsky: entry/exit params (k,4) of incident edges q → q+1, and their validity."""
    dx, dy = np.roll(x, -1, axis=1) - x, np.roll(y, -1, axis=1) - y
    hu, hv = hu[:, None], hv[:, None]
    p = np.stack((-dx, dx, -dy, dy))  # constraints p·t ≤ q: x ≥ −hu, x ≤ hu, y ≥ −hv, y ≤ hv
    q = np.stack((x + hu, hu - x, y + hv, hv - y))
    ratio = safe_div(q, p)
    enter = np.maximum(np.where(p < 0.0, ratio, 0.0).max(axis=0), 0.0)
    leave = np.minimum(np.where(p > 0.0, ratio, 1.0).min(axis=0), 1.0)
    # Zero-length steps along a constraint (p == 0) reject the edge if it lies outside.
    outside = ((np.abs(p) <= 1e-12) & (q < -_CLIP_TOL)).any(axis=0)
    length = np.hypot(dx, dy)
    tol = safe_div(np.full_like(length, 10.0 * _CLIP_TOL), length)
    valid = ~outside & (enter <= leave)
    return enter, leave, valid & (enter > tol), valid & (leave < 1.0 - tol)


def _corners_inside(x: np.ndarray, y: np.ndarray, hu: np.ndarray, hv: np.ndarray) -> np.ndarray:
    """Reference corners (k,4,2) and which lie strictly inside the incident quad (k,4)."""
    corner = _QUAD[None] * np.stack((hu, hv), axis=1)[:, None, :]
    ex, ey = np.roll(x, -1, axis=1) - x, np.roll(y, -1, axis=1) - y
    rx = corner[:, :, None, 0] - x[:, None, :]  # (k, corner, edge)
    ry = corner[:, :, None, 1] - y[:, None, :]
    side = safe_div(ex[:, None] * ry - ey[:, None] * rx, np.hypot(ex, ey)[:, None])
    inside = (side > _CLIP_TOL).all(axis=2) | (side < -_CLIP_TOL).all(axis=2)
    return corner, inside


def face_manifold(
    n: np.ndarray,
    fc: np.ndarray,
    fu: np.ndarray,
    fv: np.ndarray,
    hu: np.ndarray,
    hv: np.ndarray,
    incident: tuple[np.ndarray, np.ndarray, np.ndarray],
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Manifold of reference face (normal n, centre fc, axes fu, fv, halves hu, hv) against
    the incident box (centre, rotation, half): points on the incident face (k,16,3),
    depths (k,16), candidates present (k,16).  Features as in the module docstring."""
    w, m = _incident_quad(n, *incident)
    rel = w - fc[:, None, :]
    x, y, z = dot(rel, fu[:, None]), dot(rel, fv[:, None]), dot(rel, n[:, None])
    vert_in = (np.abs(x) <= hu[:, None] + _CLIP_TOL) & (np.abs(y) <= hv[:, None] + _CLIP_TOL)
    corner, corner_in = _corners_inside(x, y, hu, hv)
    # Height of the incident plane m·(p − w₀) = 0 above the reference corners.
    mu, mv, mn = dot(m, fu)[:, None], dot(m, fv)[:, None], dot(m, n)[:, None]
    zc = safe_div(dot(m, w[:, 0] - fc)[:, None] - corner[..., 0] * mu - corner[..., 1] * mv, mn)
    pc = fc[:, None] + corner[..., :1] * fu[:, None] + corner[..., 1:] * fv[:, None]
    pc = pc + zc[..., None] * n[:, None]
    enter, leave, enter_ok, leave_ok = _clip_edges(x, y, hu, hv)
    t = np.stack((enter, leave), axis=2).reshape(-1, 8)  # columns 2q, 2q + 1
    q = np.repeat(np.arange(4), 2)
    dw = np.roll(w, -1, axis=1) - w
    pe = w[:, q] + t[..., None] * dw[:, q]
    ze = z[:, q] + t * (np.roll(z, -1, axis=1) - z)[:, q]
    point = np.concatenate((w, pc, pe), axis=1)
    depth = -np.concatenate((z, zc, ze), axis=1)
    edge_ok = np.stack((enter_ok, leave_ok), axis=2).reshape(-1, 8)
    return point, depth, np.concatenate((vert_in, corner_in, edge_ok), axis=1)


def _reference_face(best: np.ndarray, axis: np.ndarray, boxes: tuple[np.ndarray, ...]):
    """Reference-face frame from the chosen face axis (0–2 a's, 3–5 b's; edges use a's 0)."""
    ca, ra, ha, cb, rb, hb = boxes
    on_b = (best >= 3) & (best < 6)
    i = np.where(best < 6, best % 3, 0)
    rows = np.arange(len(best))
    rr, hr = np.where(on_b[:, None, None], rb, ra), np.where(on_b[:, None], hb, ha)
    n = np.where(on_b[:, None], -axis, axis)  # outward from the reference box
    iu, iv = (i + 1) % 3, (i + 2) % 3
    fc = np.where(on_b[:, None], cb, ca) + n * hr[rows, i][:, None]
    incident = (
        np.where(on_b[:, None], ca, cb),
        np.where(on_b[:, None, None], ra, rb),
        np.where(on_b[:, None], ha, hb),
    )
    frame = (n, fc, rr[rows, :, iu], rr[rows, :, iv], hr[rows, iu], hr[rows, iv])
    return on_b, frame, incident


def edge_contact(best: np.ndarray, axis: np.ndarray, boxes: tuple[np.ndarray, ...]):
    """Midpoint (k,3) of the closest points of the supporting edges (best: axes 6–14)."""
    ca, ra, ha, cb, rb, hb = boxes
    ia, ib = (best - 6) // 3, (best - 6) % 3
    rows = np.arange(len(best))

    def support(c, rot, half, i, towards):
        sign = np.where(np.einsum("kij,ki->kj", rot, towards) >= 0.0, 1.0, -1.0)
        sign[rows, i] = -1.0
        start = c + np.einsum("kij,kj->ki", rot, sign * half)
        return start, 2.0 * half[rows, i][:, None] * rot[rows, :, i]

    pa, ea = support(ca, ra, ha, ia, axis)
    pb, eb = support(cb, rb, hb, ib, -axis)
    s, t = segment_params(pa, ea, pb, eb)
    return 0.5 * (pa + s[:, None] * ea + pb + t[:, None] * eb)


def box_box(
    ca: np.ndarray,
    ra: np.ndarray,
    ha: np.ndarray,
    cb: np.ndarray,
    rb: np.ndarray,
    hb: np.ndarray,
    margin: float,
) -> Found:
    """Box a (centre, rotation, half extents) against box b: up to 8 contacts (16 features)."""
    boxes = (ca, ra, ha, cb, rb, hb)
    sep, best, axis = separating_axis(*boxes)
    on_b, frame, incident = _reference_face(best, axis, boxes)
    point, depth, keep = face_manifold(*frame, incident)
    n = frame[0][:, None, :]
    point = point + n * (0.5 * depth)[..., None]
    normal = np.broadcast_to(np.where(on_b[:, None, None], -n, n), point.shape).copy()
    is_edge = best >= 6
    keep &= (~is_edge & (sep <= margin))[:, None] & (depth >= -margin)
    # Face axis but the faces' projections miss each other (boxes diagonally apart):
    # keep the incident vertex deepest along n, whose gap is the axis' separation.
    bare = ~keep.any(axis=1) & ~is_edge & (sep <= margin)
    keep[bare, depth[bare, :4].argmax(axis=1)] = True
    if is_edge.any():
        edge_boxes = tuple(x[is_edge] for x in boxes)
        point[is_edge, 0] = edge_contact(best[is_edge], axis[is_edge], edge_boxes)
    normal[is_edge, 0] = axis[is_edge]
    depth[is_edge, 0] = -sep[is_edge]
    keep[is_edge, 0] = sep[is_edge] <= margin
    return point, normal, depth, keep
