"""Compiled row building (solver.rows.build.build_rows's twin): every row of a step, in the
numpy step's order (joints, contacts, the pointer's, pins).
"""

from __future__ import annotations

from solver.collide.pointer_kernel import collide_pointer
from solver.collide.scene_kernel import collide_scene
from solver.compiled.clock import cycles, tick
from solver.compiled.layout import Coupling, Flags, IOpt, Opt, Pointer
from solver.jit import kernel
from solver.kin_kernel import quat_from, scale, sub, vec_from
from solver.rows.contacts_kernel import contact_rows
from solver.rows.grip_kernel import MODE_GRIP, MODE_TOUCH, coupling_rows
from solver.rows.joints_kernel import anchor_rows, limit_rows, rheology_rows
from solver.rows.pin_kernel import pin_rows
from solver.rows.table_kernel import ZERO


@kernel(error_model="numpy", inline="always")
def build_rows(joints, rheo, limits, g, opt, iopt, st, rot, vel_free, inp, ws, asleep, awake,
               limit_scratch):  # fmt: skip
    """Fill the row table; returns (rows, scene contacts, first grip row, grip rows), or
    rows = −1 for a shape pair it does not know.  The shapes' world frames (ws.shape_centre,
    ws.shape_rot) are already computed; asleep/awake (nb,) bool: sleeping bodies and the awake
    movable ones (solver.advance.sleep); limit_scratch: ``limit_rows``' (gaps, turned)."""
    pos, quat = st.x, st.q
    rw, rheo_joint, cb, centre, srot = (
        ws.rows,
        ws.rheo_joint,
        ws.contacts,
        ws.shape_centre,
        ws.shape_rot,
    )
    pvec, cvec, ivec = inp.pointer, inp.coupling, inp.flags
    h = opt[Opt.h]
    prof, on = ws.cycles, iopt[IOpt.profiling]
    t = cycles() if on else 0
    n = anchor_rows(joints, pos, rot, st.omega, h, opt[Opt.joint_erp], True, asleep, rw, 0)
    if iopt[IOpt.has_rheology]:
        n = rheology_rows(
            rheo, quat, rot, h, st.q_sf, st.yielded, st.anchor, asleep, rheo_joint, rw, n
        )
    if iopt[IOpt.has_limits]:
        gaps, turned = limit_scratch
        n = limit_rows(
            limits,
            quat,
            rot,
            h,
            opt[Opt.joint_erp],
            opt[Opt.limit_margin],
            asleep,
            rw,
            n,
            gaps,
            turned,
        )
    tick(prof, on, 2, t)
    ncontact = 0
    if iopt[IOpt.has_collision]:
        ncontact = collide_scene(
            g, centre, srot, opt[Opt.contact_margin], cb, iopt[IOpt.cull_pairs], awake
        )
        if ncontact < 0:
            return -1, 0, 0, 0
        n = contact_rows(
            cb,
            0,
            ncontact,
            pos,
            vel_free,
            ZERO,
            h,
            opt[Opt.contact_erp],
            opt[Opt.contact_slop],
            rw,
            n,
        )
    if ivec[Flags.mode] == MODE_GRIP:
        ptr = (vec_from(pvec, Pointer.pos), quat_from(pvec, Pointer.quat),
               vec_from(pvec, Pointer.vel), vec_from(pvec, Pointer.omega))  # fmt: skip
        cpl = (
            vec_from(cvec, Coupling.anchor), vec_from(cvec, Coupling.offset),
            quat_from(cvec, Coupling.rest), cvec[Coupling.stiffness], cvec[Coupling.damping],
            cvec[Coupling.rot_stiffness], cvec[Coupling.rot_damping],
            cvec[Coupling.force_limit], cvec[Coupling.torque_limit],
        )  # fmt: skip
        grip0 = n
        n = coupling_rows(
            pos, quat, h, ptr, cpl, ivec[Flags.body], ivec[Flags.position_only], rw, n
        )
        ngrip = n - grip0
        n = pin_rows(inp.pins, inp.pin_bone, pos, quat, rot, st.omega, h, opt[Opt.joint_erp],
                     awake, rw, n)  # fmt: skip
        return n, ncontact, grip0, ngrip
    if ivec[Flags.mode] == MODE_TOUCH:
        u = vec_from(pvec, Pointer.vel)
        pc = sub(vec_from(pvec, Pointer.pos), scale(h, u))  # where the pointer was
        end = collide_pointer(
            g, centre, srot, pc, pvec[Pointer.radius], opt[Opt.contact_margin], cb, ncontact
        )
        n = contact_rows(
            cb,
            ncontact,
            end,
            pos,
            vel_free,
            u,
            h,
            opt[Opt.contact_erp],
            opt[Opt.contact_slop],
            rw,
            n,
        )
    grip0 = n
    n = pin_rows(inp.pins, inp.pin_bone, pos, quat, rot, st.omega, h, opt[Opt.joint_erp], awake,
                 rw, n)  # fmt: skip
    return n, ncontact, grip0, 0
