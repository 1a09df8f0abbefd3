"""The compiled step: ``solver.pipeline.step``'s pipeline in one call (DESIGN §3, digest §4.3).

    v_free  = v + h (g + F/m),  ω_free = ω + h I_w⁻¹ τ
    rows    = anchor | rheology | limits | contacts (normal, friction) | grip or pointer
    lam     = direct (tree elimination inside an active set: rows leaving their box are
              pinned at the bound, released when they stop pushing on it; PGS finishes
              if that does not settle) when every row is two-sided; else PGS
              warm-started with last step's λ by row key
    v, pose = integrate (momentum form), project joints (only above 0.1 mm)
    q_sf    = rheology update with the solved velocity; warm keys sorted for the next step

Packed arguments (see ``solver.compiled.pack``): m model arrays, g geometry, tree the
elimination forest, ws/pws workspaces, opt/iopt options, st state arrays, inp input.
Status FALLBACK hands the step back to the numpy implementation (box–box contact, a
monitor failure that must raise, a degenerate direct system); SUBSTEP asks for
rep_i[0] equal substeps (solver.advance.substep) before anything is computed.
"""

from __future__ import annotations

import numpy as np

from solver.advance.integrate_kernel import free_velocity, integrate
from solver.advance.monitor_kernel import gaps_within, state_ok
from solver.advance.rheology_kernel import rheology_update
from solver.advance.sleep import settle
from solver.advance.sleep_kernel import flowing_joints, wake
from solver.advance.stabilize_kernel import needs_projection, project
from solver.advance.substep import substeps_needed
from solver.collide.scene_kernel import world_shapes
from solver.compiled.clock import cycles, tick
from solver.compiled.flat import node_count, row_capacity, unflatten
from solver.jit import kernel
from solver.kin_kernel import frames
from solver.rows.build_kernel import build_rows
from solver.rows.grip_kernel import MODE_TOUCH, is_touch_row
from solver.rows.joints_kernel import limit_arrays
from solver.rows.table import KIND_GRIP
from solver.solve.dispatch_kernel import FALLBACK, OK, SUBSTEP, regularize, solve, warm_table
from solver.solve.hybrid_kernel import NU_CAP


@kernel(error_model="numpy", _nrt=False)
def report(rw, n, lam, rep_f):
    """rep_f[1:4] grip force, [4:7] grip torque, [7:10] pointer touch force."""
    for i in range(n):
        if rw[11][i] == KIND_GRIP:
            slot = rw[10][i] & 0xF
            rep_f[1 + slot] = lam[i]
        elif is_touch_row(rw[10][i], rw[11][i]):
            for k in range(3):
                rep_f[7 + k] += rw[3][i, k] * lam[i]


@kernel(error_model="numpy")
def step_kernel(flat, st, inp, out, rep_i, rep_f):
    """One step of st into the caller's arrays (entry points: ``solver.compiled.entry``).

    st (x, q, v, ω, q_sf, yielded, anchor, τ_avg, warm keys, warm λ, asleep, still);
    out (x, q, v, ω, q_sf, yielded, anchor, τ_avg, τ, asleep, still) is written and must not
    share memory with st (read throughout, intact when the step is handed back); rep_i (4,) (rows,
    contacts, iterations, solver) and rep_f (10,) (residual, grip f, grip τ, touch f) are
    zeroed, then filled.  Returns (status, out, warm keys, warm λ, rep_i, rep_f); the warm
    keys and λ must be fresh arrays (fast_step keeps them in the State, and the model's
    arrays are views that must not reach Python: solver.compiled.flat).

    This function makes the step's arrays; the step itself is ``_step``, compiled without
    numba's reference counting (``_nrt=False``): with it, every array bound to a name in
    the inlined parts, and every array of a tuple handed to one, cost two calls to NRT's
    counters (~4,400 a step on the doll, ~11 % of its time), although the model's views
    have no owner to count.  Whatever allocates runs in functions of its own that keep
    the counting (the projection, the substep test, sleeping, a Schur complement of more
    than hybrid.NU_CAP rows); the solvers work in the step's scratch arrays."""
    nodes = node_count(flat)
    scratch, keys, values = step_arrays(len(st[0]), len(st[4]), row_capacity(flat), nodes)
    status, count = _step(flat, st, inp, out, rep_i, rep_f, scratch, keys, values)
    if status != OK:
        return _handed_back(status, out, rep_i, rep_f)
    return OK, out, keys[:count], values[:count], rep_i, rep_f


@kernel(error_model="numpy")
def step_arrays(nb, nj, rows, nodes):
    """The arrays ``_step`` works in, for nb bodies, nj joints, room for ``rows`` rows and
    a forest of ``nodes`` nodes: (scratch, warm keys, warm λ), scratch as ``_step`` reads
    it.  step_kernel makes them every step; a Sim once, kept in its flat buffers
    (entry.SIM_SCHEMA)."""
    b, i = np.bool_, np.int64
    solvers = (
        (np.empty(rows, b), np.empty(rows, b), np.empty(rows, b)),
        (np.empty(rows, i), np.empty(rows, i), np.empty(rows, i), np.empty(rows, i),
         np.empty(nodes, i), np.empty(nodes, i), np.empty(6, i)),
        (np.empty(rows), np.empty(rows), np.empty(rows), np.empty(rows), np.empty(rows),
         np.empty(rows), np.empty(rows)),
        (np.empty((nb, 6)), np.empty((nb, 6))),
        np.empty(NU_CAP * NU_CAP),
    )  # fmt: skip
    scratch = (
        np.empty((nb, 6)), np.empty(nb, b), np.empty(nb, b), (np.empty(nb, b), np.empty(4)),
        np.empty(rows), np.empty(rows), np.empty((nb, 6)),
        (np.empty((nb, 3)), np.empty((nb, 3)), np.empty(nb, b)),
        np.empty((nj, 3)), (np.empty((nj, 3)), np.empty((nj, 3))), np.empty(nj, b), solvers,
    )  # fmt: skip
    return scratch, np.empty(rows, np.int64), np.empty(rows)


@kernel(error_model="numpy", _nrt=False)
def _step(flat, st, inp, out, rep_i, rep_f, scratch, keys, values):
    """``step_kernel``'s step, the model's packed tuples rebuilt from its flat buffers
    here (solver.compiled.flat); returns (status, warm rows in keys/values).  The step's parts
    that take those tuples are inlined into it (``inline="always"``) or called, compiled
    without reference counting too.  scratch: v_free (nb,6), fresh and awake (nb,) bool,
    wake's (loaded, pointer), warm λ and λ (rows), v (nb,6), integrate's, rheology's w
    (nj,3), limit_rows' (gaps, turned), flowing joints (nj,) bool, the solvers' (``solve``):
    whatever they hold on entry (a Sim passes the same arrays every step:
    ``step_arrays``) is overwritten before it is read."""
    m, g, tree, ptree, ws, pws, opt, iopt = unflatten(flat)
    vel_free, fresh, awake, wake_scratch, lam0, lam, vel = scratch[:7]
    integrate_scratch, w, limit_scratch, flows, sv = scratch[7:]
    pos, quat = st[0], st[1]
    nb = len(pos)
    rw, rot, inv_i, inertia_w = ws[0], ws[5], ws[6], ws[7]
    joints = (
        m[0],
        m[1],
        m[2],
        m[3],
    )  # parents, bones, anchors (solver.advance.stabilize_kernel.gap2)
    rheo = (m[0], m[1], m[4], m[5], m[6], m[7], m[12], m[13], m[14])  # post.rheology_update
    out[5][:] = False
    fresh[:] = False
    rep_i[:] = 0
    rep_f[:] = 0
    prof, on = ws[10], iopt[7]
    t = cycles() if on else 0
    nsub = substeps_needed(opt[0], iopt[6], m[0], m[1], m[16], m[20], st[8], st[9])
    if nsub > 1:
        rep_i[0] = nsub
        return SUBSTEP, 0
    frames(quat, m[17], m[18], rot, inertia_w, inv_i)
    if iopt[5] or inp[4][0] == MODE_TOUCH or iopt[10]:
        world_shapes(g, pos, quat, ws[8], ws[9])
    asleep = out[9]
    wake(m[19], (g[0], g[6], g[7], g[8]), opt, iopt, st, inp, ws[8], out[9], out[10], fresh,
         wake_scratch)  # fmt: skip
    movable = m[16]
    for b in range(nb):
        awake[b] = movable[b] > 0.0 and not asleep[b]
    t = tick(prof, on, 0, t)
    free_velocity(m[16], opt, st[2], st[3], inv_i, (inp[0], inp[1], inp[4]), vel_free)
    for b in range(nb):
        if asleep[b]:
            vel_free[b, :] = 0.0
    t = tick(prof, on, 1, t)
    joint_part = prof[2]
    n, ncontact, grip0, ngrip = build_rows(
        joints, rheo, limit_arrays(m), g, opt, iopt, st, rot, vel_free, inp, ws, asleep, awake,
        limit_scratch,
    )  # fmt: skip
    if n < 0:
        return FALLBACK, 0
    t = tick(prof, on, 3, t + (prof[2] - joint_part))  # build_rows timed its joint rows (2)
    regularize(rw, n, m[16], inv_i, opt[0], opt[6])
    t = tick(prof, on, 4, t)
    grip = (grip0, ngrip, inp[4][1])
    bw = (m[1], m[15], m[16], ws[1], ws[2], inv_i, inertia_w)
    status, iters, residual, used = solve(
        bw, tree, rw, opt, iopt, (st[8], st[9]), n, vel_free, grip, asleep, sv, lam0, lam, vel
    )
    t = tick(prof, on, 5, t)
    if status or not state_ok(joints, opt, pos, quat, vel[:, :3], vel[:, 3:], False):
        return FALLBACK, 0
    integrate(m[17], m[18], opt[0], pos, quat, vel, rot, asleep, out[0], out[1], out[3],
              integrate_scratch)  # fmt: skip
    projected = needs_projection(joints, out[0], out[1], asleep)
    if projected and not project(m, joints, ptree, pws, out[0], out[1], asleep):
        return FALLBACK, 0
    gaps_known = gaps_within(projected, opt)
    if not state_ok(joints, opt, out[0], out[1], vel[:, :3], out[3], gaps_known):
        return FALLBACK, 0
    for b in range(nb):  # (an array assigned to a slice needs reference counting)
        for k in range(3):
            out[2][b, k] = vel[b, k]
    t = tick(prof, on, 6, t)
    rheology_update(rheo, opt, st[4:8], rw, n, lam, vel, ws[3], out[1], asleep, out[4:9], w)
    if iopt[10]:
        flowing_joints(m[7], m[13], m[14], out[5], flows)
        settle(m[19], asleep, out[10], out[2], out[3], m[1], flows, opt[0], opt[15], opt[16],
               opt[17], fresh)  # fmt: skip
    count = warm_table(rw, n, lam, keys, values)
    rep_i[0], rep_i[1], rep_i[2], rep_i[3] = count, ncontact, iters, used
    rep_f[0] = residual
    report(rw, n, lam, rep_f)
    tick(prof, on, 7, t)
    return OK, count


@kernel(error_model="numpy")
def _handed_back(status, out, rep_i, rep_f):
    """step_kernel's result for a step it hands back: no warm keys or λ (the empty
    arrays made only then, not every step)."""
    return status, out, np.empty(0, dtype=np.int64), np.empty(0), rep_i, rep_f
