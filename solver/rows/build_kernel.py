"""Compiled row building (solver.rows.build.build_rows's twin): every row of a step, in the
numpy step's order.
"""

from __future__ import annotations

from solver.collide.pointer_kernel import collide_pointer
from solver.collide.scene_kernel import collide_scene
from solver.compiled.clock import cycles, tick
from solver.jit import kernel
from solver.rows.contacts_kernel import contact_rows
from solver.rows.grip_kernel import MODE_GRIP, MODE_TOUCH, coupling_rows
from solver.rows.joints_kernel import anchor_rows, limit_rows, rheology_rows
from solver.rows.table_kernel import ZERO


@kernel(error_model="numpy", inline="always")
def build_rows(joints, rheo, limits, g, opt, iopt, st, rot, vel_free, inp, ws, asleep, awake,
               limit_scratch):  # fmt: skip
    """Fill the row table; returns (rows, scene contacts, first grip row, grip rows), or
    rows = −1 when a box–box pair is within reach.  The shapes' world frames (ws[8],
    ws[9]) are already computed; asleep/awake (nb,) bool: sleeping bodies and the awake
    movable ones (solver.advance.sleep); limit_scratch: ``limit_rows``' (gaps, turned)."""
    pos, quat = st[0], st[1]
    rw, rheo_joint, cb, centre, srot = ws[0], ws[3], ws[4], ws[8], ws[9]
    pvec, cvec, ivec = inp[2], inp[3], inp[4]
    h = opt[0]
    prof, on = ws[10], iopt[7]
    t = cycles() if on else 0
    n = anchor_rows(joints, pos, rot, st[3], h, opt[1], True, asleep, rw, 0)
    if iopt[3]:
        n = rheology_rows(rheo, quat, rot, h, st[4], st[5], st[6], asleep, rheo_joint, rw, n)
    if iopt[4]:
        gaps, turned = limit_scratch
        n = limit_rows(limits, quat, rot, h, opt[1], opt[5], asleep, rw, n, gaps, turned)
    tick(prof, on, 2, t)
    ncontact = 0
    if iopt[5]:
        ncontact = collide_scene(g, centre, srot, opt[4], cb, iopt[8], awake)
        if ncontact < 0:
            return -1, 0, 0, 0
        n = contact_rows(cb, 0, ncontact, pos, vel_free, ZERO, h, opt[2], opt[3], rw, n)
    if ivec[0] == MODE_GRIP:
        ptr = (
            (pvec[0], pvec[1], pvec[2]),
            (pvec[3], pvec[4], pvec[5], pvec[6]),
            (pvec[7], pvec[8], pvec[9]),
            (pvec[10], pvec[11], pvec[12]),
        )
        cpl = (
            (cvec[0], cvec[1], cvec[2]),
            (cvec[3], cvec[4], cvec[5]),
            (cvec[6], cvec[7], cvec[8], cvec[9]),
            cvec[10],
            cvec[11],
            cvec[12],
            cvec[13],
            cvec[14],
            cvec[15],
        )
        grip0 = n
        n = coupling_rows(pos, quat, h, ptr, cpl, ivec[1], ivec[2], rw, n)
        return n, ncontact, grip0, n - grip0
    if ivec[0] == MODE_TOUCH:
        u = (pvec[7], pvec[8], pvec[9])
        pc = (pvec[0] - h * u[0], pvec[1] - h * u[1], pvec[2] - h * u[2])
        end = collide_pointer(g, centre, srot, pc, pvec[13], opt[4], cb, ncontact)
        n = contact_rows(cb, ncontact, end, pos, vel_free, u, h, opt[2], opt[3], rw, n)
    return n, ncontact, n, 0
