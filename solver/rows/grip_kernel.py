"""Compiled grip coupling rows (solver.rows.grip's twin)."""

from __future__ import annotations

from solver.collide.pointer_kernel import POINTER_KEY_OFFSET
from solver.jit import kernel
from solver.kin_kernel import (
    add,
    clip,
    cross,
    dot,
    norm,
    qconj,
    qlog,
    qmul,
    qrotate,
    quat_at,
    scale,
    sub,
    vec,
)
from solver.rows.table import KEY_SHIFT, KIND_CONTACT, KIND_FRICTION, KIND_GRIP
from solver.rows.table_kernel import AXES, ZERO, angular_jac, point_jac, set_row


@kernel(error_model="numpy")
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


@kernel(error_model="numpy")
def is_touch_row(key, kind):
    """Contact or friction row of the pointer sphere (identity ≥ 2³²)."""
    ident = key & ((1 << KEY_SHIFT) - 1)
    return kind >= KIND_CONTACT and kind <= KIND_FRICTION and ident >= POINTER_KEY_OFFSET


MODE_NONE, MODE_GRIP, MODE_TOUCH = 0, 1, 2


@kernel(error_model="numpy")
def segment_distances(pos, quat, pos0, head0, tail0, point, out):
    """solver.rows.grip.segment_distances's distances, the same floats, into out (nbone,):
    from ``point`` to each bone's head–tail axis, the bones at (pos, quat) of rest pose
    pos0 with rest ends head0, tail0."""
    for b in range(out.shape[0]):
        q, p, rest = quat_at(quat, b), vec(pos, b), vec(pos0, b)
        head = add(p, qrotate(q, sub(vec(head0, b), rest)))
        seg = sub(add(p, qrotate(q, sub(vec(tail0, b), rest))), head)
        length2 = max(dot(seg, seg), 1e-18)
        s = clip(dot(sub(point, head), seg) / length2, 0.0, 1.0)
        out[b] = norm(sub(add(head, scale(s, seg)), point))
