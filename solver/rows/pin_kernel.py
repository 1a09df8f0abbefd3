"""Compiled pin rows (solver.rows.pin's twin): the same rows in the same order."""

from __future__ import annotations

from solver.compiled.layout import PinVec
from solver.jit import kernel
from solver.kin_kernel import (
    add,
    matvec,
    qconj,
    qlog,
    qmul,
    quat_at,
    quat_from,
    scale,
    sub,
    vec,
    vec_from,
)
from solver.rows.joints_kernel import arc_offset
from solver.rows.pin import SLOTS
from solver.rows.table import KIND_PIN
from solver.rows.table_kernel import AXES, ZERO, angular_jac, point_jac, set_row


@kernel(error_model="numpy", _nrt=False)
def pin_rows(pins, pin_bone, pos, quat, rot, omega, h, erp, awake, rw, n):
    """Rows of every pin (pins (npin, layout.PinVec), pin_bone (npin,)) whose bone is
    awake and movable (awake (nb,) bool): 3 position rows, then 3 orientation rows when
    the pin holds the orientation; returns the next row."""
    for p in range(len(pin_bone)):
        b = pin_bone[p]
        if not awake[b]:
            continue
        r = matvec(rot, b, vec_from(pins[p], PinVec.point))
        gap = scale(erp, sub(add(vec(pos, b), r), vec_from(pins[p], PinVec.target)))
        gap = add(gap, arc_offset(vec(omega, b), r, h))
        lim = pins[p, PinVec.force_limit]
        for k in range(3):
            ja, jb = point_jac(AXES[k], ZERO, r)
            set_row(rw, n, KIND_PIN, SLOTS * b + k, -1, b, ja, jb, -lim, lim, 0.0, gap[k] / h,
                    -1, 0.0)  # fmt: skip
            n += 1
        if pins[p, PinVec.orient] == 0.0:
            continue
        turn = qlog(qmul(quat_at(quat, b), qconj(quat_from(pins[p], PinVec.target_quat))))
        lim = pins[p, PinVec.torque_limit]
        for k in range(3):
            ja, jb = angular_jac(AXES[k])
            set_row(rw, n, KIND_PIN, SLOTS * b + 3 + k, -1, b, ja, jb, -lim, lim, 0.0,
                    erp * turn[k] / h, -1, 0.0)  # fmt: skip
            n += 1
    return n
