"""Compiled sleeping (solver.advance.sleep's twin for the step's wake and flowing joints)."""

from __future__ import annotations

from solver.advance.sleep import touch
from solver.jit import kernel
from solver.rows.grip_kernel import MODE_GRIP, MODE_TOUCH
from solver.rows.joints_kernel import flowing


@kernel(error_model="numpy", inline="always")
def wake(island, shapes, opt, iopt, st, inp, centre, asleep, still, fresh, scratch):
    """asleep, still (nb,) ← the state's, then wake what this step touches (solver.advance.sleep:
    loads, the grip, a free pointer, moving neighbours); all awake when sleeping is off.
    island: m[19]; shapes: the geometry's shape bodies, bounds and pairs (g[0], g[6],
    g[7], g[8]); scratch: (loaded (nb,) bool, pointer (4,))."""
    nb, was_asleep, was_still = len(asleep), st[10], st[11]
    for b in range(nb):
        asleep[b], still[b] = (was_asleep[b], was_still[b]) if iopt[10] else (False, 0.0)
    if not iopt[10]:
        return
    force, torque, pvec, ivec = inp[0], inp[1], inp[2], inp[4]
    loaded, pointer = scratch
    loaded[:] = False
    for b in range(nb):
        for k in range(3):
            if (ivec[3] and force[b, k] != 0.0) or (ivec[4] and torque[b, k] != 0.0):
                loaded[b] = True
    pointer[:] = 0.0
    if ivec[0] == MODE_TOUCH:
        for k in range(3):
            pointer[k] = pvec[k] - opt[0] * pvec[7 + k]
        pointer[3] = pvec[13]
    grip_body = ivec[1] if ivec[0] == MODE_GRIP else -1
    shape_body, bound, pair_f, pair_s = shapes
    touch(island, asleep, still, fresh, loaded, grip_body, pointer, centre, bound, shape_body,
          pair_f, pair_s, opt[4], st[2], st[3], opt[15], opt[16])  # fmt: skip


@kernel(error_model="numpy", inline="always")
def flowing_joints(has, plastic, finite_yield, yielded, out):
    """out (nj,) bool ← joints with rheology on the three-element rows
    (solver.rows.joints.flowing); has, plastic, finite_yield: m[7], m[13], m[14]."""
    nj = len(has)
    for j in range(nj):
        out[j] = has[j] and flowing(plastic, finite_yield, yielded, j)
    return out
