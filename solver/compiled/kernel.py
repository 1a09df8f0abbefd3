"""The compiled step: ``solver.pipeline.step``'s pipeline in one call (DESIGN §3, digest §4.3).

    v_free  = v + h (g + F/m),  ω_free = ω + h I_w⁻¹ τ
    rows    = anchor | rheology | limits | contacts (normal, friction) | grip or pointer
    lam     = direct (tree elimination inside an active set: rows leaving their box are
              pinned at the bound, released when they stop pushing on it; PGS finishes
              if that does not settle) when every row is two-sided; else PGS
              warm-started with last step's λ by row key
    v, pose = integrate (momentum form), project joints (only above stabilize.projection_tol)
    q_sf    = rheology update with the solved velocity; warm keys sorted for the next step

Packed arguments (see ``solver.compiled.pack``): m model arrays, g geometry, tree the
elimination forest, ws/pws workspaces, opt/iopt options, st state arrays, inp input.
Status FALLBACK hands the step back to the numpy implementation (a monitor failure
that must raise, a degenerate direct system).  ``_step`` returns SUBSTEP
(rep_i[ReportInt.rows] equal substeps: solver.advance.substep) or RESTART (a BDF2 step
without history: solver.advance.bdf2_kernel.RESTART's parts) before anything is computed;
the entry points then take the step in those parts here (``step_parts``), so neither
status leaves the kernel.

Under ``integrator: bdf2`` the same pipeline runs as the BDF2 stage (solver.advance.bdf2):
from the predicted end pose (``_stage``), with opt's h = γ, the rows' velocity shift
(solver.rows.shift_kernel), the stage's integration, and the history written into out.
"""

from __future__ import annotations

import numpy as np

from solver.advance.bdf2_kernel import RESTART as RESTART_PARTS
from solver.advance.bdf2_kernel import integrate_stage, load_mark, predict, ratio, remember
from solver.advance.integrate_kernel import free_velocity, integrate
from solver.advance.monitor_kernel import gaps_within, state_ok
from solver.advance.rheology_kernel import rheology_update
from solver.advance.sleep import settle
from solver.advance.sleep_kernel import flowing_joints, wake
from solver.advance.stabilize import projection_tol
from solver.advance.stabilize_kernel import needs_projection, project
from solver.advance.substep import moved_back, substeps_needed
from solver.collide.scene_kernel import world_shapes
from solver.compiled.clock import cycles, tick
from solver.compiled.flat import node_count, row_capacity
from solver.compiled.layout import (
    Bodies,
    Flags,
    Input,
    IntegrateScratch,
    IOpt,
    Joints,
    LimitScratch,
    Opt,
    Pointer,
    Prediction,
    ReportFloat,
    ReportInt,
    Rheology,
    Scratch,
    SolverFlags,
    SolverIndex,
    SolverScratch,
    SolverValues,
    StateSet,
    StepState,
    WakeScratch,
)  # fmt: skip
from solver.compiled.views import packed_view
from solver.jit import kernel
from solver.kin_kernel import frames
from solver.rows.build_kernel import build_rows
from solver.rows.grip_kernel import MODE_NONE, MODE_TOUCH, is_touch_row
from solver.rows.joints_kernel import limit_arrays
from solver.rows.shift_kernel import shift_rows
from solver.rows.table import KIND_GRIP
from solver.solve.dispatch_kernel import (
    FALLBACK,
    OK,
    RESTART,
    SUBSTEP,
    regularize,
    solve,
    warm_table,
)
from solver.solve.hybrid_kernel import NU_CAP

_OPT_SIZE = int(Opt.SIZE)
_POINTER_SIZE, _REPORT_SIZE = int(Pointer.SIZE), int(ReportFloat.SIZE)


@kernel(error_model="numpy", _nrt=False)
def report(rw, n, lam, rep_f):
    """rep_f's grip force and torque and pointer touch force (layout.ReportFloat)."""
    for i in range(n):
        if rw.kind[i] == KIND_GRIP:
            slot = rw.key[i] & 0xF
            rep_f[ReportFloat.grip_force + slot] = lam[i]  # force, then torque
        elif is_touch_row(rw.key[i], rw.kind[i]):
            for k in range(3):
                rep_f[ReportFloat.touch_force + k] += rw.jac_b[i, k] * lam[i]


@kernel(error_model="numpy")
def step_kernel(flat, st, inp, out, rep_i, rep_f):
    """One step of st into the caller's arrays (entry points: ``solver.compiled.entry``).

    st (layout.StepState) is read; out (layout.StateSet) is written and must not share
    memory with st (read throughout, intact when the step is handed back); rep_i and rep_f
    (layout.ReportInt, ReportFloat) are zeroed, then filled.  Returns (status, out, warm
    keys, warm λ, rep_i, rep_f); the warm keys and λ must be fresh arrays (fast_step keeps
    them in the State, and the model's arrays are views that must not reach Python:
    solver.compiled.flat).

    This function makes the step's arrays; the step itself is ``_step``, compiled without
    numba's reference counting (``_nrt=False``): with it, every array bound to a name in
    the inlined parts, and every array of a tuple handed to one, cost two calls to NRT's
    counters (~4,400 a step on the doll, ~11 % of its time), although the model's views
    have no owner to count.  Whatever allocates runs in functions of its own that keep
    the counting (the projection, the substep test, sleeping, a Schur complement of more
    than hybrid.NU_CAP rows); the solvers work in the step's scratch arrays."""
    nodes = node_count(flat)
    scratch, keys, values = step_arrays(len(st.x), len(st.q_sf), row_capacity(flat), nodes)
    status, count = _step(flat, st, inp, out, rep_i, rep_f, scratch, keys, values, 0)
    if status in (SUBSTEP, RESTART):
        spare = _state_set_like(out)
        spare_keys, spare_values = np.empty_like(keys), np.empty_like(values)
        status, count = step_parts(flat, st, inp, (out, spare), rep_i, rep_f, scratch,
                                   (keys, values, spare_keys, spare_values), status)  # fmt: skip
    if status != OK:
        return _handed_back(status, out, rep_i, rep_f)
    return OK, out, keys[:count], values[:count], rep_i, rep_f


@kernel(error_model="numpy")
def step_arrays(nb, nj, rows, nodes):
    """The arrays ``_step`` works in, for nb bodies, nj joints, room for ``rows`` rows and
    a forest of ``nodes`` nodes: (layout.Scratch, warm keys, warm λ).  step_kernel makes
    them every step; a Sim once, kept in its flat buffers (layout.SimArrays)."""
    b, i = np.bool_, np.int64
    solvers = SolverScratch(
        SolverFlags(np.empty(rows, b), np.empty(rows, b), np.empty(rows, b), np.empty(rows, b),
                    np.empty(rows, b)),
        SolverIndex(np.empty(rows, i), np.empty(rows, i), np.empty(rows, i), np.empty(rows, i),
                    np.empty(nodes, i), np.empty(nodes, i), np.empty(6, i), np.empty(rows, i),
                    np.empty(rows, i)),
        SolverValues(np.empty(rows), np.empty(rows), np.empty(rows), np.empty(rows),
                     np.empty(rows), np.empty(rows), np.empty(rows)),
        np.empty((nb, 6)), np.empty((nb, 6)), np.empty(NU_CAP * NU_CAP), np.empty(nb, b),
    )  # fmt: skip
    pred = Prediction(np.empty((nb, 3)), np.empty((nb, 4)), np.empty((nb, 3)), np.empty((nb, 3)),
                      np.empty((nb, 6)), np.empty((nj, 3)))  # fmt: skip
    scratch = Scratch(
        np.empty((nb, 6)), np.empty(nb, b), np.empty(nb, b),
        WakeScratch(np.empty(nb, b), np.empty(4)), np.empty(rows), np.empty(rows),
        np.empty((nb, 6)), IntegrateScratch(np.empty((nb, 3)), np.empty((nb, 3)), np.empty(nb, b)),
        np.empty((nj, 3)), LimitScratch(np.empty((nj, 3)), np.empty((nj, 3))), np.empty(nj, b),
        solvers, pred, np.empty((nb, 6)), np.empty(_OPT_SIZE), np.empty(_OPT_SIZE),
        np.empty(_POINTER_SIZE), np.empty(_REPORT_SIZE),
    )  # fmt: skip
    return scratch, np.empty(rows, np.int64), np.empty(rows)


@kernel(error_model="numpy", _nrt=False)
def _step(flat, st, inp, out, rep_i, rep_f, scratch, keys, values, d):
    """``step_kernel``'s step, the model's packed structures rebuilt from its flat buffers
    here (solver.compiled.views); returns (status, warm rows in keys/values).  d = 0: a
    whole step; d > 0: a part of one (``step_parts``), h/d, never subdivided.  The step's
    parts that take those structures are inlined into it (``inline="always"``) or called,
    compiled without reference counting too.  scratch (layout.Scratch): whatever it holds
    on entry (a Sim passes the same arrays every step: ``step_arrays``) is overwritten
    before it is read."""
    packed = packed_view(flat, 0)
    m, g, ws, opt, iopt = packed.m, packed.g, packed.ws, packed.opt, packed.iopt
    sv = scratch.solvers
    vel_free, fresh, awake, lam0, lam, vel = (
        scratch.vel_free, scratch.fresh, scratch.awake, scratch.lam0, scratch.lam, scratch.vel,
    )  # fmt: skip
    pos, quat = st.x, st.q
    nb = len(pos)
    rw, rot, inv_i, inertia_w = ws.rows, ws.rot, ws.inv_inertia, ws.inertia
    joints = Joints(m.joint_parent, m.joint_bone, m.joint_anchor_parent, m.joint_anchor_child)
    rheo = Rheology(m.joint_parent, m.joint_bone, m.joint_kf, m.joint_df, m.joint_dd,
                    m.joint_rheology, m.joint_yield, m.joint_plastic,
                    m.joint_finite_yield)  # fmt: skip
    out.yielded[:] = False
    fresh[:] = False
    rep_i[:] = 0
    rep_f[:] = 0
    prof, on = ws.cycles, iopt[IOpt.profiling]
    t = cycles() if on else 0
    whole = d == 0
    if whole:
        nsub = substeps_needed(opt[Opt.h], iopt[IOpt.max_substeps], m.joint_parent,
                               m.joint_bone, m.body_inv_mass, m.joint_levers, st.warm_key,
                               st.warm_lam)  # fmt: skip
        if nsub > 1:
            rep_i[ReportInt.rows] = nsub
            return SUBSTEP, 0
    else:  # solver.advance.substep.sub_model's options
        part_opt = scratch.part_opt
        for k in range(len(opt)):
            part_opt[k] = opt[k]
        part_opt[Opt.h] = opt[Opt.h] / d
        opt = part_opt
    # The stage: the paper's step from st, or BDF2's from the predicted end pose.
    bdf, pred = iopt[IOpt.bdf2], scratch.pred
    stage, sopt, load = st, opt, 0.0
    if bdf:
        ivec = inp.flags
        load = load_mark(inp.force, inp.torque, ivec[Flags.has_force], ivec[Flags.has_torque],
                         ivec[Flags.mode], ivec[Flags.body], inp.coupling)  # fmt: skip
        r = ratio(opt, st, st.hist, load)
        if r == 0.0 and whole and iopt[IOpt.max_substeps] > 1:
            return RESTART, 0  # solver.advance.bdf2.RESTART's parts
        stage, sopt = _stage(m, opt, st, r, pred, rot, scratch.stage_opt)
    frames(stage.q, m.body_inertia, m.body_inv_inertia, rot, inertia_w, inv_i)
    touch = inp.flags[Flags.mode] == MODE_TOUCH
    shapes_needed = iopt[IOpt.has_collision] or touch
    if shapes_needed or iopt[IOpt.sleep]:
        world_shapes(g, pos, quat, ws.shape_centre, ws.shape_rot)
    asleep = out.asleep
    shapes = (g.shape_body, g.shape_bound, g.pair_first, g.pair_second)
    wake(m.body_island, shapes, opt, iopt, st, inp, ws.shape_centre, out.asleep, out.still,
         fresh, scratch.wake)  # fmt: skip
    movable = m.body_inv_mass
    for b in range(nb):
        awake[b] = movable[b] > 0.0 and not asleep[b]
    t = tick(prof, on, 0, t)
    loads = (inp.force, inp.torque, inp.flags)
    free_velocity(m.body_inv_mass, sopt, stage.v, stage.omega, inv_i, loads, vel_free)
    for b in range(nb):
        if asleep[b]:
            vel_free[b, :] = 0.0
            pred.shift[b, :] = 0.0
    moving = vel_free
    if bdf:
        moving = scratch.moving
        for b in range(nb):
            for k in range(6):
                moving[b, k] = vel_free[b, k] + pred.shift[b, k]
        if shapes_needed:
            world_shapes(g, stage.x, stage.q, ws.shape_centre, ws.shape_rot)
    t = tick(prof, on, 1, t)
    joint_part = prof[2]
    n, ncontact, grip0, ngrip = build_rows(
        joints, rheo, limit_arrays(m), g, sopt, iopt, stage, rot, moving, inp, ws, asleep, awake,
        scratch.limit,
    )  # fmt: skip
    if n < 0:
        return FALLBACK, 0
    if bdf:
        flowing_joints(m.joint_rheology, m.joint_plastic, m.joint_finite_yield, st.yielded,
                       scratch.flows)  # fmt: skip
        shift_rows(rw, n, pred.shift, m.joint_df, scratch.flows, inp.coupling)
    t = tick(prof, on, 3, t + (prof[2] - joint_part))  # build_rows timed its joint rows (2)
    regularize(rw, n, m.body_inv_mass, inv_i, sopt[Opt.h], opt[Opt.regularization])
    t = tick(prof, on, 4, t)
    grip = (grip0, ngrip, inp.flags[Flags.body])
    bw = Bodies(m.joint_bone, m.body_mass, m.body_inv_mass, ws.resp_a, ws.resp_b, inv_i,
                inertia_w)  # fmt: skip
    status, iters, residual, used = solve(
        bw, packed.tree, rw, sopt, iopt, (st.warm_key, st.warm_lam), n, vel_free, grip, asleep,
        sv, lam0, lam, vel,
    )  # fmt: skip
    t = tick(prof, on, 5, t)
    if status:
        return FALLBACK, 0
    if bdf:
        integrate_stage(m.body_inertia, m.body_inv_inertia, sopt[Opt.h], pred, vel, rot, asleep,
                        out.x, out.q, out.omega)  # fmt: skip
        _keep_asleep(asleep, pos, quat, out.x, out.q, out.omega)
    if not state_ok(joints, opt, pos, quat, vel[:, :3], vel[:, 3:], False):
        return FALLBACK, 0
    if not bdf:
        integrate(m.body_inertia, m.body_inv_inertia, opt[Opt.h], pos, quat, vel, rot, asleep,
                  out.x, out.q, out.omega, scratch.integrate)  # fmt: skip
    tol = projection_tol(opt[Opt.h])
    projected = needs_projection(joints, out.x, out.q, asleep, tol)
    if projected and not project(m, joints, packed.ptree, packed.pws, out.x, out.q, asleep, tol):
        return FALLBACK, 0
    gaps_known = gaps_within(projected, opt, tol)
    if not state_ok(joints, opt, out.x, out.q, vel[:, :3], out.omega, gaps_known):
        return FALLBACK, 0
    for b in range(nb):  # (an array assigned to a slice needs reference counting)
        for k in range(3):
            out.v[b, k] = vel[b, k]
    t = tick(prof, on, 6, t)
    prev = (stage.q_sf, st.yielded, st.anchor, st.torque_avg)
    new = (out.q_sf, out.yielded, out.anchor, out.torque_avg, out.torque)
    rheology_update(rheo, sopt, prev, rw, n, lam, vel, ws.rheo_joint, out.q, asleep, new,
                    scratch.w)  # fmt: skip
    if iopt[IOpt.sleep]:
        flowing_joints(m.joint_rheology, m.joint_plastic, m.joint_finite_yield, out.yielded,
                       scratch.flows)  # fmt: skip
        settle(m.body_island, asleep, out.still, out.v, out.omega, m.joint_bone, scratch.flows,
               opt[Opt.h], opt[Opt.sleep_speed], opt[Opt.sleep_spin], opt[Opt.sleep_time],
               fresh)  # fmt: skip
    if bdf:
        remember(opt[Opt.h], load, st, out, st.yielded)
    count = warm_table(rw, n, lam, keys, values)
    rep_i[ReportInt.rows], rep_i[ReportInt.contacts] = count, ncontact
    rep_i[ReportInt.iterations], rep_i[ReportInt.solver] = iters, used
    rep_i[ReportInt.substeps] = 1
    rep_f[ReportFloat.residual] = residual
    report(rw, n, lam, rep_f)
    tick(prof, on, 7, t)
    return OK, count


@kernel(error_model="numpy", _nrt=False)
def step_parts(flat, st, inp, sets, rep_i, rep_f, scratch, warm, status):
    """A whole step taken in parts, as solver.advance.substep.run_parts takes it: on
    SUBSTEP rep_i's rows entry n equal parts h/n, on RESTART the parts RESTART_PARTS; each
    part ``_step``'s at h/d with the input's pointer at the part's end (moved back along its
    velocity).  sets: (out, spare) layout.StateSets; warm: (keys, values, spare keys, spare
    values).  The parts write out and spare in turn, so that the last writes out and
    keys/values; st is only read.  The report: the last part's rows, contacts and solver,
    the parts' summed iterations and largest residual, their mean grip and touch forces,
    and their count as substeps.  Returns (status, warm rows), as ``_step``."""
    out, spare = sets
    keys, values, spare_keys, spare_values = warm
    restart = status == RESTART
    n = len(RESTART_PARTS) if restart else rep_i[ReportInt.rows]
    h = packed_view(flat, 0).opt[Opt.h]
    summed, done, iterations, residual, count = scratch.part_report, 0.0, 0, 0.0, 0
    summed[:] = 0.0
    here = st
    for k in range(n):
        d = RESTART_PARTS[k] if restart else n
        done += h / d
        part = _part_input(inp, max(h - done, 0.0), scratch.part_pointer)
        into_out = (n - 1 - k) % 2 == 0  # so that the last part writes out
        target = out if into_out else spare
        wk, wv = (keys, values) if into_out else (spare_keys, spare_values)
        status, count = _step(flat, here, part, target, rep_i, rep_f, scratch, wk, wv, d)
        if status != OK:
            return status, 0
        iterations += rep_i[ReportInt.iterations]
        residual = max(residual, rep_f[ReportFloat.residual])
        for i in range(len(summed)):
            summed[i] += rep_f[i]
        here = step_state(target, wk[:count], wv[:count])
    rep_i[ReportInt.iterations], rep_i[ReportInt.substeps] = iterations, n
    for i in range(len(summed)):
        rep_f[i] = summed[i] / n
    rep_f[ReportFloat.residual] = residual
    return OK, count


@kernel(error_model="numpy", _nrt=False)
def _part_input(inp, before_end, pointer):
    """inp with its pointer ``before_end`` seconds before the step's end, moved back along
    its velocity (solver.advance.substep.pointer_at) into ``pointer``; inp itself when
    before_end is 0 or no pointer is read."""
    if before_end == 0.0 or inp.flags[Flags.mode] == MODE_NONE:
        return inp
    p = inp.pointer
    for k in range(len(pointer)):
        pointer[k] = p[k]
    pos, q = moved_back(p[Pointer.pos : Pointer.quat], p[Pointer.quat : Pointer.vel],
                        p[Pointer.vel : Pointer.omega], p[Pointer.omega : Pointer.radius],
                        before_end)  # fmt: skip
    for k in range(3):
        pointer[Pointer.pos + k] = pos[k]
    for k in range(4):
        pointer[Pointer.quat + k] = q[k]
    return Input(inp.force, inp.torque, pointer, inp.coupling, inp.flags, inp.pins, inp.pin_bone)


@kernel(error_model="numpy", inline="always")
def step_state(prev, keys, lam):
    """The step's st (layout.StepState): a StateSet's fields (τ is not read) with the warm
    keys and λ."""
    return StepState(prev.x, prev.q, prev.v, prev.omega, prev.q_sf, prev.yielded, prev.anchor,
                     prev.torque_avg, keys, lam, prev.asleep, prev.still, prev.prev_x,
                     prev.prev_q, prev.prev_v, prev.prev_omega, prev.prev_q_sf,
                     prev.hist)  # fmt: skip


@kernel(error_model="numpy")
def _state_set_like(out):
    """A layout.StateSet of fresh arrays shaped as out's."""
    e, o = np.empty_like, out
    return StateSet(e(o.x), e(o.q), e(o.v), e(o.omega), e(o.q_sf), e(o.yielded), e(o.anchor),
                    e(o.torque_avg), e(o.torque), e(o.asleep), e(o.still), e(o.prev_x),
                    e(o.prev_q), e(o.prev_v), e(o.prev_omega), e(o.prev_q_sf),
                    e(o.hist))  # fmt: skip


@kernel(error_model="numpy", _nrt=False)
def _stage(m, opt, st, r, pred, rot, stage_opt):
    """(the stage's StepState, its opt) of a BDF2 step from st at step ratio r
    (solver.advance.bdf2): pred (layout.Prediction) and stage_opt (opt with h = γ and the
    yield filter's time constant scaled by γ/h) are written; rot (nb,3,3) scratch."""
    history = (st.prev_x, st.prev_q, st.prev_v, st.prev_omega, st.prev_q_sf)
    h = opt[Opt.h]
    gamma = predict(m.body_inertia, m.body_inv_inertia, h, r, st, history, rot, pred)
    for k in range(len(opt)):
        stage_opt[k] = opt[k]
    stage_opt[Opt.h] = gamma
    stage_opt[Opt.yield_filter_time] = opt[Opt.yield_filter_time] * gamma / h
    stage = StepState(pred.x, pred.q, pred.v, pred.omega, pred.q_sf, st.yielded, st.anchor,
                      st.torque_avg, st.warm_key, st.warm_lam, st.asleep, st.still, st.prev_x,
                      st.prev_q, st.prev_v, st.prev_omega, st.prev_q_sf, st.hist)  # fmt: skip
    return stage, stage_opt


@kernel(error_model="numpy", _nrt=False)
def _keep_asleep(asleep, pos, quat, out_pos, out_quat, out_omega):
    """Sleeping bodies keep their pose, at rest."""
    for b in range(len(pos)):
        if asleep[b]:
            for k in range(3):
                out_pos[b, k], out_omega[b, k] = pos[b, k], 0.0
            for k in range(4):
                out_quat[b, k] = quat[b, k]


@kernel(error_model="numpy")
def _handed_back(status, out, rep_i, rep_f):
    """step_kernel's result for a step it hands back: no warm keys or λ (the empty
    arrays made only then, not every step)."""
    return status, out, np.empty(0, dtype=np.int64), np.empty(0), rep_i, rep_f
