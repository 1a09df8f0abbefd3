"""Compiled checks after a step (solver.advance.monitor's twin): finite state, speeds,
joint gaps."""

from __future__ import annotations

from solver.advance.stabilize_kernel import gap2
from solver.compiled.layout import Opt
from solver.jit import kernel


@kernel(error_model="numpy", inline="always")
def gaps_within(projected, opt, tol):
    """After integration and ``project``: every anchor gap is known to be within the
    monitor's limit without measuring it, when nothing needed projecting (every awake
    joint within the step's projection trigger ``tol``, and that within the limit) — the
    sleeping joints have not moved since the step's first check (``state_ok`` on its start
    pose)."""
    return not projected and opt[Opt.max_joint_gap] >= tol


@kernel(error_model="numpy", _nrt=False)
def state_ok(joints, opt, pos, quat, lin, ang, gaps_known):
    """False when the monitor (solver.advance.monitor.check_state) would raise; joints as
    ``gap2``'s.  Branch-free over the bodies: 0·x is 0 for every finite x and NaN
    otherwise, so one sum tests them all; speeds, spins and anchor gaps are compared
    squared.  gaps_known: every anchor gap is already known to be within the limit
    (the caller's ``gaps_within``), so they are not measured again."""
    poison, fast = 0.0, False
    max_speed2, max_spin2 = (
        opt[Opt.max_speed] * opt[Opt.max_speed],
        opt[Opt.max_angular_speed] * opt[Opt.max_angular_speed],
    )
    for b in range(len(pos)):
        for k in range(3):
            poison += 0.0 * pos[b, k] + 0.0 * lin[b, k] + 0.0 * ang[b, k]
        for k in range(4):
            poison += 0.0 * quat[b, k]
        speed2 = lin[b, 0] * lin[b, 0] + lin[b, 1] * lin[b, 1] + lin[b, 2] * lin[b, 2]
        spin2 = ang[b, 0] * ang[b, 0] + ang[b, 1] * ang[b, 1] + ang[b, 2] * ang[b, 2]
        fast = fast or speed2 > max_speed2 or spin2 > max_spin2
    if poison != 0.0 or fast:  # (NaN != 0)
        return False
    if gaps_known:
        return True
    limit2 = opt[Opt.max_joint_gap] * opt[Opt.max_joint_gap]
    within = True
    for j in range(len(joints.parent)):
        within = within and gap2(joints, pos, quat, j) <= limit2
    return within
