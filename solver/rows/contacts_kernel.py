"""Compiled contact rows (solver.rows.contacts's twin): one normal row per contact point,
and two friction rows when it has friction.
"""

from __future__ import annotations

from solver.jit import kernel
from solver.kin_kernel import (
    add,
    cross,
    dot,
    norm,
    scale,
    sub,
    vec,
)
from solver.rows.table import KIND_CONTACT, KIND_FRICTION
from solver.rows.table_kernel import INF, ZERO, point_jac, set_row


@kernel(error_model="numpy")
def _point_velocity(vel, b, r):
    if b < 0:
        return ZERO
    return add((vel[b, 0], vel[b, 1], vel[b, 2]), cross((vel[b, 3], vel[b, 4], vel[b, 5]), r))


@kernel(error_model="numpy")
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


@kernel(error_model="numpy")
def contact_rows(cb, c0, c1, pos, vel_free, u, h, erp, slop, rw, n):
    """Normal rows of contacts c0..c1−1, then the friction pairs of those with friction
    (μ > 0); u: static side's velocity."""
    first = n
    for i in range(c0, c1):
        a, b = cb.body_a[i], cb.body_b[i]
        point, normal, d = vec(cb.point, i), vec(cb.normal, i), cb.depth[i]
        r_a = sub(point, vec(pos, a)) if a >= 0 else point
        r_b = sub(point, vec(pos, b)) if b >= 0 else point
        bias = -d / h if d < 0.0 else -erp * max(d - slop, 0.0) / h
        ja, jb = point_jac(normal, r_a, r_b)
        set_row(
            rw,
            n,
            KIND_CONTACT,
            cb.key[i],
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
        if not cb.friction[i] > 0.0:
            continue
        a, b = cb.body_a[i], cb.body_b[i]
        point, normal = vec(cb.point, i), vec(cb.normal, i)
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
                2 * cb.key[i] + k,
                a,
                b,
                ja,
                jb,
                -INF,
                INF,
                0.0,
                -dot(tangents[k], u),
                first + i - c0,
                cb.friction[i],
            )
            n += 1
    return n
