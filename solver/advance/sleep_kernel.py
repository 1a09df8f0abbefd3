"""Compiled sleeping (solver.advance.sleep's twin for the step's wake and flowing joints)."""

from __future__ import annotations

from solver.advance.sleep import touch
from solver.compiled.layout import Flags, IOpt, Opt, Pointer
from solver.jit import kernel
from solver.rows.grip_kernel import MODE_GRIP, MODE_TOUCH
from solver.rows.joints_kernel import flowing


@kernel(error_model="numpy", inline="always")
def wake(island, shapes, opt, iopt, st, inp, centre, asleep, still, fresh, scratch):
    """asleep, still (nb,) ← the state's, then wake what this step touches (solver.advance.sleep:
    loads, the grip, a free pointer, moving neighbours); all awake when sleeping is off.
    island: m.body_island; shapes: the geometry's shape bodies, bounds and pairs
    (g.shape_body, g.shape_bound, g.pair_first, g.pair_second); scratch (layout.WakeScratch):
    loaded (nb,) bool, pointer (4,)."""
    nb, was_asleep, was_still = len(asleep), st.asleep, st.still
    for b in range(nb):
        asleep[b], still[b] = (was_asleep[b], was_still[b]) if iopt[IOpt.sleep] else (False, 0.0)
    if not iopt[IOpt.sleep]:
        return
    force, torque, pvec, ivec = inp.force, inp.torque, inp.pointer, inp.flags
    loaded, pointer = scratch
    loaded[:] = False
    for b in range(nb):
        for k in range(3):
            if (ivec[Flags.has_force] and force[b, k] != 0.0) or (
                ivec[Flags.has_torque] and torque[b, k] != 0.0
            ):
                loaded[b] = True
    pointer[:] = 0.0
    if ivec[Flags.mode] == MODE_TOUCH:
        for k in range(3):
            pointer[k] = pvec[Pointer.pos + k] - opt[Opt.h] * pvec[Pointer.vel + k]
        pointer[3] = pvec[Pointer.radius]
    grip_body = ivec[Flags.body] if ivec[Flags.mode] == MODE_GRIP else -1
    shape_body, bound, pair_f, pair_s = shapes
    touch(island, asleep, still, fresh, loaded, grip_body, pointer, centre, bound, shape_body,
          pair_f, pair_s, opt[Opt.contact_margin], st.v, st.omega, opt[Opt.sleep_speed],
          opt[Opt.sleep_spin])  # fmt: skip


@kernel(error_model="numpy", inline="always")
def flowing_joints(has, plastic, finite_yield, yielded, out):
    """out (nj,) bool ← joints with rheology on the three-element rows
    (solver.rows.joints.flowing); has, plastic, finite_yield: m.joint_rheology,
    m.joint_plastic, m.joint_finite_yield."""
    nj = len(has)
    for j in range(nj):
        out[j] = has[j] and flowing(plastic, finite_yield, yielded, j)
    return out
