"""Compiled collision driver, contact rows and grip coupling rows.

Collision (``solver.collide``): shape k's world centre and rotation are
c = x_B + R(q_B)·shape_pos, q = q_B ⊗ shape_quat (static shapes: as given).  A pair
(first f, second s, ordered plane < sphere = capsule < box) is tested only when its
bounding spheres come within the margin: for a plane f, n_f·(c_s − c_f) − bound_s ≤ margin,
otherwise |c_s − c_f| − bound_f − bound_s ≤ margin.  Contacts come out sorted by key
= pair·16 + feature because pairs and features are visited in that order.  The free-mode
pointer is a static sphere against every body shape, keys offset by 2³²
(``solver.touch``).

Contact rows (``solver.contact_rows``): normal rows first, then two friction rows per
contact along t1 (the would-be tangential slip of v_free, or a fixed tangent at rest)
and t2 = n × t1, bounded by ±μ λ_n.  Normal bias −d/h for a gap, −erp·max(d − slop, 0)/h
when penetrating, minus n·u for a static side moving at u (the pointer).

Grip rows (``solver.grip``): Voigt rows C = 1/(D + K h), bias (K e' − D u)·C with
e' = bone point − pointer target (then log(q_b ⊗ q_target⁻¹) for rotation).
"""

from __future__ import annotations

from numba import njit

from solver.fast.kin import (
    add,
    column,
    cross,
    dot,
    norm,
    put,
    qconj,
    qlog,
    qmatrix,
    qmul,
    qrotate,
    quat_at,
    scale,
    sub,
    vec,
)
from solver.fast.narrow import plane_box, plane_segment, segment_box, segment_segment
from solver.fast.rows import AXES, INF, ZERO, angular_jac, point_jac, set_row
from solver.rows import KEY_SHIFT, KIND_CONTACT, KIND_FRICTION, KIND_GRIP

PLANE, BOX = 0, 3
GROUP_PLANE_SEGMENT, GROUP_PLANE_BOX, GROUP_SEGMENT_SEGMENT, GROUP_SEGMENT_BOX = range(4)
POINTER_KEY_OFFSET = 1 << 32
Y_AXIS = (0.0, 1.0, 0.0)


@njit(cache=True, error_model="numpy")
def world_shapes(g, body_pos, body_quat, centre, rot):
    """World centres (ns,3) and rotations (ns,3,3) of all shapes into centre, rot."""
    shape_body, shape_pos, shape_quat = g[0], g[1], g[2]
    for k in range(len(shape_body)):
        b = shape_body[k]
        if b >= 0:
            bq = quat_at(body_quat, b)
            put(centre, k, add(vec(body_pos, b), qrotate(bq, vec(shape_pos, k))))
            qmatrix(qmul(bq, quat_at(shape_quat, k)), rot, k)
        else:
            put(centre, k, vec(shape_pos, k))
            qmatrix(quat_at(shape_quat, k), rot, k)


@njit(cache=True, error_model="numpy", _nrt=False)
def collide_scene(g, centre, rot, margin, cb, cull, awake):
    """Contacts of the scene's candidate pairs into cb; returns the count, or −1 when a
    box–box pair is within reach (not compiled: the caller falls back to numpy).  With
    ``cull``, pairs whose bounding spheres are farther apart than the margin are skipped
    before the narrow phase (which would find nothing there either); pairs with no
    awake movable body (awake (nb,) bool: solver.sleep) are skipped altogether."""
    kind, radius, half, bound = g[3], g[4], g[5], g[6]
    pair_f, pair_s, group, sign, body_a, body_b, mu = g[7], g[8], g[9], g[10], g[11], g[12], g[13]
    n = 0
    for p in range(len(pair_f)):
        f, s = pair_f[p], pair_s[p]
        if not ((body_a[p] >= 0 and awake[body_a[p]]) or (body_b[p] >= 0 and awake[body_b[p]])):
            continue
        if cull and not _within_reach(kind[f] == PLANE, centre, rot, f, s, bound, margin):
            continue
        ctx = (body_a[p], body_b[p], mu[p], sign[p], p * 16)
        grp = group[p]
        cf, cs = vec(centre, f), vec(centre, s)
        af, as_ = column(rot, f, 1), column(rot, s, 1)  # axes: plane normal, segment axis
        if grp == GROUP_PLANE_SEGMENT:
            n = plane_segment(cf, af, cs, as_, half[s, 1], radius[s], margin, ctx, cb, n)
        elif grp == GROUP_PLANE_BOX:
            n = plane_box(cf, af, cs, rot, s, vec(half, s), margin, ctx, cb, n)
        elif grp == GROUP_SEGMENT_SEGMENT:
            seg_f, seg_s = (cf, af, half[f, 1], radius[f]), (cs, as_, half[s, 1], radius[s])
            n = segment_segment(*seg_f, *seg_s, margin, ctx, cb, n)
        elif grp == GROUP_SEGMENT_BOX:
            seg_f = (cf, af, half[f, 1], radius[f])
            n = segment_box(cs, rot, s, vec(half, s), *seg_f, margin, ctx, cb, n)
        else:
            return -1
    return n


@njit(cache=True, error_model="numpy")
def _within_reach(plane, centre, rot, f, s, bound, margin):
    """Shape s's bounding sphere within the margin of shape f's (or of f's plane): for
    two spheres |offset| ≤ r_f + r_s + margin, compared squared (no square root)."""
    offset = sub(vec(centre, s), vec(centre, f))
    if plane:
        return dot(offset, column(rot, f, 1)) - bound[s] <= margin
    reach = bound[f] + bound[s] + margin
    return dot(offset, offset) <= reach * reach


@njit(cache=True, error_model="numpy")
def collide_pointer(g, centre, rot, pc, pr, margin, cb, n):
    """Contacts of the pointer sphere (centre pc, radius pr) with every body shape."""
    shape_body, kind, radius, half, bound, shapes, mu = g[0], g[3], g[4], g[5], g[6], g[14], g[15]
    for rank in range(len(shapes)):
        k = shapes[rank]
        if not (norm(sub(vec(centre, k), pc)) - pr) - bound[k] <= margin:
            continue
        ctx = (-1, shape_body[k], mu[rank], 1.0, POINTER_KEY_OFFSET + rank * 16)
        ck = vec(centre, k)
        if kind[k] == BOX:
            n = segment_box(ck, rot, k, vec(half, k), pc, Y_AXIS, 0.0, pr, margin, ctx, cb, n)
        else:
            n = segment_segment(
                pc,
                Y_AXIS,
                0.0,
                pr,
                ck,
                column(rot, k, 1),
                half[k, 1],
                radius[k],
                margin,
                ctx,
                cb,
                n,
            )
    return n


@njit(cache=True, error_model="numpy")
def _point_velocity(vel, b, r):
    if b < 0:
        return ZERO
    return add((vel[b, 0], vel[b, 1], vel[b, 2]), cross((vel[b, 3], vel[b, 4], vel[b, 5]), r))


@njit(cache=True, error_model="numpy")
def tangent_basis(normal, slip):
    """(t1, t2): t1 along the tangential part of slip when it has one (> 1e-9)."""
    t = sub(slip, scale(dot(slip, normal), normal))
    length = norm(t)
    if length > 1e-9:
        s = max(length, 1e-300)
        t1 = (t[0] / s, t[1] / s, t[2] / s)
    else:
        ref = (1.0, 0.0, 0.0) if abs(normal[0]) < 0.9 else (0.0, 0.0, 1.0)
        fixed = cross(normal, ref)
        s = norm(fixed)
        t1 = (fixed[0] / s, fixed[1] / s, fixed[2] / s)
    return t1, cross(normal, t1)


@njit(cache=True, error_model="numpy")
def contact_rows(cb, c0, c1, pos, vel_free, u, h, erp, slop, rw, n):
    """Normal rows of contacts c0..c1−1, then their friction pairs; u: static side's velocity."""
    first = n
    for i in range(c0, c1):
        a, b = cb[0][i], cb[1][i]
        point, normal, d = vec(cb[2], i), vec(cb[3], i), cb[4][i]
        r_a = sub(point, vec(pos, a)) if a >= 0 else point
        r_b = sub(point, vec(pos, b)) if b >= 0 else point
        bias = -d / h if d < 0.0 else -erp * max(d - slop, 0.0) / h
        ja, jb = point_jac(normal, r_a, r_b)
        set_row(
            rw,
            n,
            KIND_CONTACT,
            cb[6][i],
            a,
            b,
            ja,
            jb,
            0.0,
            INF,
            0.0,
            bias - dot(normal, u),
            -1,
            0.0,
        )
        n += 1
    for i in range(c0, c1):
        a, b = cb[0][i], cb[1][i]
        point, normal = vec(cb[2], i), vec(cb[3], i)
        r_a = sub(point, vec(pos, a)) if a >= 0 else point
        r_b = sub(point, vec(pos, b)) if b >= 0 else point
        slip = sub(sub(_point_velocity(vel_free, b, r_b), _point_velocity(vel_free, a, r_a)), u)
        tangents = tangent_basis(normal, slip)
        for k in range(2):
            ja, jb = point_jac(tangents[k], r_a, r_b)
            set_row(
                rw,
                n,
                KIND_FRICTION,
                2 * cb[6][i] + k,
                a,
                b,
                ja,
                jb,
                -INF,
                INF,
                0.0,
                -dot(tangents[k], u),
                first + i - c0,
                cb[5][i],
            )
            n += 1
    return n


@njit(cache=True, error_model="numpy")
def coupling_rows(pos, quat, h, ptr, cpl, body, position_only, rw, n):
    """Grip rows: 3 translation rows at the grip point, then 3 rotation rows.

    ptr = (pos, quat, vel, omega) of the pointer; cpl = (anchor, offset, rest, K, D,
    K_rot, D_rot, force limit, torque limit)."""
    p_pos, p_quat, p_vel, p_omega = ptr
    anchor, offset, rest, k_lin, d_lin, k_rot, d_rot, f_lim, t_lim = cpl
    qb = quat_at(quat, body)
    r_b = qrotate(qb, anchor)
    target = add(p_pos, qrotate(p_quat, offset))
    u = add(p_vel, cross(p_omega, sub(target, p_pos)))
    e = sub(add(vec(pos, body), r_b), target)
    s = d_lin + k_lin * h
    comp = 1.0 / s
    for k in range(3):
        ja, jb = point_jac(AXES[k], ZERO, r_b)
        bias = k_lin * e[k] / s - d_lin * u[k] * comp
        set_row(rw, n, KIND_GRIP, k, -1, body, ja, jb, -f_lim, f_lim, comp, bias, -1, 0.0)
        n += 1
    if position_only:
        return n
    e_rot = qlog(qmul(qb, qconj(qmul(p_quat, rest))))
    s = d_rot + k_rot * h
    comp = 1.0 / s
    for k in range(3):
        ja, jb = angular_jac(AXES[k])
        bias = k_rot * e_rot[k] / s - d_rot * p_omega[k] * comp
        set_row(rw, n, KIND_GRIP, 3 + k, -1, body, ja, jb, -t_lim, t_lim, comp, bias, -1, 0.0)
        n += 1
    return n


@njit(cache=True, error_model="numpy")
def is_touch_row(key, kind):
    """Contact or friction row of the pointer sphere (identity ≥ 2³²)."""
    ident = key & ((1 << KEY_SHIFT) - 1)
    return kind >= KIND_CONTACT and kind <= KIND_FRICTION and ident >= POINTER_KEY_OFFSET
