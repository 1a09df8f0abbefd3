"""One simulation step (DESIGN §3, digest §4.3):

frames   = kinematics(model, state)
contacts = collide(...)                      only when the scene has collision pairs
rows     = anchor | rheology | limits | contacts   (rheology only for joints that have it)
lam      = solve(rows, v_free, warm start)   auto: direct when every row is two-sided,
                                             else hybrid (joints exact, bounded rows by
                                             PGS on their Schur complement); or PGS
n        = substeps(forces, inertia)         equal substeps when the joints' geometric
                                             stiffness needs them (solver.advance.substep)
v, pose  = integrate(...)
q_sf     = rheology_update(rows, v)          with the SOLVED velocity w_s[t+1]
"""

from __future__ import annotations

from dataclasses import replace
from functools import partial

import numpy as np

from solver import quat
from solver.advance import bdf2
from solver.advance.bdf2_kernel import RESTART
from solver.advance.integrate import free_velocity, integrate_pose
from solver.advance.monitor import check_state
from solver.advance.rheology import rheology_update
from solver.advance.sleep import body_islands, settle, wake
from solver.advance.stabilize import project_joints
from solver.advance.substep import model_substeps, run_parts, run_substeps, sub_model
from solver.collide.pointer import POINTER_KEY_OFFSET
from solver.errors import SimulationError
from solver.model import Model
from solver.rows.build import build_rows
from solver.rows.grip import coupling_wrench
from solver.rows.joints import flowing
from solver.rows.pin import with_pins
from solver.rows.shift import shifted, velocity_share
from solver.rows.table import KEY_SHIFT, KIND_CONTACT, KIND_FRICTION, Rows
from solver.solve.dispatch import solve
from solver.solve.response import regularize, row_response, world_inverse_inertia
from solver.state import State, StepInput, StepReport


def step(model: Model, state: State, inp: StepInput | None = None) -> tuple[State, StepReport]:
    """Advance one step of size model.options.h (in equal substeps when the joints'
    geometric stiffness needs them: solver.advance.substep)."""
    inp = inp or StepInput()
    body_rot = quat.matrix(state.body_quat)
    n = model_substeps(model, state)
    if n > 1:
        return run_substeps(model, state, inp, n, partial(_part, model))
    history = None  # BDF2: (the input's fingerprint, the step ratio)
    if model.options.integrator == "bdf2":
        load = bdf2.load(inp, model.nbody)
        history = (load, bdf2.ratio(state, model.options.h, load))
        if bdf2.restarts(model, history[1]):
            return run_parts(model, state, inp, RESTART, partial(_part, model))
    return _step_once(model, state, inp, body_rot, history)


def _part(model: Model, d: int, state: State, inp: StepInput) -> tuple[State, StepReport]:
    """A step h/d of ``model`` (one of a step's parts: solver.advance.substep.run_parts)."""
    return step(sub_model(model, d), state, inp)


def _step_once(
    model: Model, state: State, inp: StepInput, body_rot: np.ndarray, history: tuple | None
) -> tuple[State, StepReport]:
    """One step without subdivision; ``history``: BDF2's (input fingerprint, step ratio),
    None for the paper's step."""
    h = model.options.h
    bdf = history is not None
    pred = bdf2.predict(model, state, history[1]) if bdf else None
    # The stage: the paper's step from the state, or BDF2's from the predicted end pose.
    sm = bdf2.stage_model(model, pred.gamma) if bdf else model
    start = bdf2.stage_state(state, pred) if bdf else state
    rot = quat.matrix(pred.quat) if bdf else body_rot
    asleep, still, fresh = wake(model, state, inp)
    inv_i = world_inverse_inertia(model.body_inv_inertia, rot)
    vel_free = free_velocity(sm, start, inp, inv_i)
    vel_free[asleep] = 0.0
    if bdf:
        pred.shift[asleep] = 0.0
    moving = vel_free + pred.shift if bdf else vel_free  # contacts' slip directions
    rows, ncontact, rheo_joint = build_rows(sm, start, rot, moving, inp, asleep)
    if bdf:
        share = velocity_share(model, rows, state.joint_yielded, inp.coupling)
        rows = shifted(rows, share, pred.shift)
    resp = row_response(rows, model.body_inv_mass, inv_i, sm.options.h)
    rows = regularize(rows, resp, model.options.regularization)
    try:
        lam, vel, iters, residual, used = solve(sm, start, rows, resp, vel_free)
    except ValueError as exc:
        raise SimulationError(str(exc), state.step, state.time, None) from None
    if bdf:  # vel becomes v[t+1] = δv + ṽ, what the monitor checks
        pos, q, vel, omega = bdf2.integrate_stage(model, pred, vel)
    check_state(model, state.step, state.time, state.body_pos, state.body_quat, vel)
    if not bdf:
        pos, q, omega = integrate_pose(model, state, vel, body_rot)
    pos[asleep], q[asleep], omega[asleep] = state.body_pos[asleep], state.body_quat[asleep], 0.0
    pos, q = project_joints(model, pos, q, asleep=asleep)
    check_state(model, state.step, state.time, pos, q, np.concatenate((vel[:, :3], omega), 1))
    rheo = rheology_update(sm, start, rows, vel, lam, rheo_joint, q)
    frozen = asleep[model.joint_bone]  # their torque reads 0: no rows
    for name in ("joint_q_sf", "joint_yielded", "joint_anchor", "joint_torque_avg"):
        rheo[name][frozen] = getattr(state, name)[frozen]
    lin = vel[:, :3].copy()
    if model.options.sleep:
        settle(
            body_islands(model), asleep, still, lin, omega, model.joint_bone,
            flowing(model, rheo["joint_yielded"]) & model.joint_rheology, h,
            model.options.sleep_speed, model.options.sleep_spin, model.options.sleep_time, fresh,
        )  # fmt: skip
    order = np.argsort(rows.key, kind="stable")
    now = dict(body_pos=pos, body_quat=q, body_vel=lin, body_omega=omega, **rheo)
    new = replace(
        state,
        time=state.time + h,
        step=state.step + 1,
        warm_key=rows.key[order],
        warm_lam=lam[order],
        body_asleep=asleep,
        body_still=still,
        **now,
        **(bdf2.history(state, h, history[0], now) if bdf else {}),
    )
    grip_force, grip_torque = coupling_wrench(rows, lam)
    report = StepReport(
        len(rows), ncontact, iters, float(residual), used, grip_force, grip_torque,
        touch_force(rows, lam),
    )  # fmt: skip
    return new, with_pins(report, inp.pins, new)


def touch_force(rows: Rows, lam: np.ndarray) -> np.ndarray:
    """Force (3,) the pointer sphere's contacts put on the bones (normal and friction)."""
    ident = rows.key & ((1 << KEY_SHIFT) - 1)
    sel = (rows.kind >= KIND_CONTACT) & (rows.kind <= KIND_FRICTION) & (ident >= POINTER_KEY_OFFSET)
    return rows.jac_b[sel, :3].T @ lam[sel]
