"""Compiled post-stabilisation of ball-joint anchors (solver.advance.stabilize's twin)."""

from __future__ import annotations

import inspect

import numpy as np

from solver.advance.stabilize import project_joints
from solver.jit import kernel
from solver.kin_kernel import (
    add,
    dot,
    frames,
    qexp,
    qmul,
    qnormalize,
    qrotate,
    quat_at,
    sub,
    vec,
)
from solver.rows.joints_kernel import anchor_rows
from solver.solve.direct_kernel import node_rows, tree_solve
from solver.solve.response_kernel import apply, response

# The numpy step's own settings, read once (numba freezes them into the compiled code;
# solver.compiled.cache recompiles when those files change).
_PROJECT = inspect.signature(project_joints).parameters


PROJECT_ROUNDS = _PROJECT["rounds"].default


PROJECT_RIDGE = 1e-14  # solver.advance.stabilize's ridge on J M⁻¹ Jᵀ


@kernel(error_model="numpy", inline="always")
def needs_projection(joints, pos, quat, asleep, tol):
    """Some awake joint's anchors are more than ``tol`` apart (``project``'s work; most
    steps: none).  joints as ``gap2``'s."""
    return awake_gap2(joints, pos, quat, asleep) > tol * tol


@kernel(error_model="numpy", _nrt=True)
def project(m, joints, tree, pws, pos, quat, asleep, tol):
    """Pull joint anchors together in place (solver.advance.stabilize.project_joints) when
    ``needs_projection`` (the caller asks first); False if the projection system is
    degenerate.  joints as ``gap2``'s; tree = (order, parent, no_rheo, rows, size, tw);
    pws = (rows, resp_a, resp_b, rot, inv_i, inertia_w, μ) scratch.  The joints of
    sleeping bodies (asleep) are left as they are."""
    order, parent, no_rheo, rows, size, tw = tree
    prw, pa, pb, rot, inv_i, inertia_w, mu = pws
    nb = len(pos)
    zeros = np.zeros((nb, 6))
    seq, nseq, bone = np.empty(len(order), np.int64), 0, m.joint_bone
    for i in order:
        if not (asleep[i] if i < nb else asleep[bone[i - nb]]):
            seq[nseq], nseq = i, nseq + 1
    for k in range(PROJECT_ROUNDS):
        if k > 0 and not needs_projection(joints, pos, quat, asleep, tol):
            break
        frames(quat, m.body_inertia, m.body_inv_inertia, rot, inertia_w, inv_i)
        n = anchor_rows(joints, pos, rot, pos, 1.0, 1.0, False, asleep, prw, 0)
        response(prw, 0, n, m.body_inv_mass, inv_i, 1.0, pa, pb)
        prw.comp[:n] = PROJECT_RIDGE
        for i in order:
            size[i] = node_rows(i, nb, no_rheo, rows[i])
        if not tree_solve(
            seq, nseq, parent, nb, prw, zeros, 1.0, m.body_mass, inertia_w, rows, size, tw, mu
        ):
            return False
        delta = np.zeros((nb, 6))
        apply(prw, n, pa, pb, mu, delta)
        for b in range(nb):
            for k in range(3):
                pos[b, k] = pos[b, k] + delta[b, k]
            q = qnormalize(qmul(qexp((delta[b, 3], delta[b, 4], delta[b, 5])), quat_at(quat, b)))
            for k in range(4):
                quat[b, k] = q[k]
    return True


@kernel(error_model="numpy", inline="always")
def gap2(joints, pos, quat, j):
    """The square of joint j's anchor distance (m²); joints: the model's joint parents,
    bones and anchors (layout.Joints).  Inlined (16–48 uses a step): called
    from a function with reference counting, each call counted its six arrays in and out
    (12 calls to NRT); the step runs without it now (kernel._step), the projection with."""
    p, c, anc_p, anc_c = joints.parent[j], joints.bone[j], joints.anchor_parent, joints.anchor_child
    a = add(vec(pos, p), qrotate(quat_at(quat, p), vec(anc_p, j))) if p >= 0 else vec(anc_p, j)
    d = sub(add(vec(pos, c), qrotate(quat_at(quat, c), vec(anc_c, j))), a)
    return dot(d, d)


@kernel(error_model="numpy", _nrt=False)
def awake_gap2(joints, pos, quat, asleep):
    """The square of the largest anchor distance (m²) of the joints of awake bodies (0
    when none); joints as ``gap2``'s."""
    worst = 0.0
    for j in range(len(joints.parent)):
        if not asleep[joints.bone[j]]:
            worst = max(worst, gap2(joints, pos, quat, j))
    return worst
