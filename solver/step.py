"""One simulation step (DESIGN §3, digest §4.3):

frames   = kinematics(model, state)
contacts = collide(...)                      only when the scene has collision pairs
rows     = anchor | rheology | limits | contacts   (rheology only for joints that have it)
lam      = solve(rows, v_free, warm start)   auto: direct when every row is two-sided,
                                             else hybrid (joints exact, bounded rows by
                                             PGS on their Schur complement); or PGS
n        = substeps(forces, inertia)         equal substeps when the joints' geometric
                                             stiffness needs them (solver.substep)
v, pose  = integrate(...)
q_sf     = rheology_update(rows, v)          with the SOLVED velocity w_s[t+1]
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from solver import collide, quat
from solver.compliance import three_element_update
from solver.contact_rows import contact_rows
from solver.direct import direct_solve
from solver.errors import SimulationError
from solver.grip import coupling_rows, coupling_wrench
from solver.hybrid import hybrid_solve
from solver.integrate import free_velocity, integrate_pose
from solver.joints import (
    anchor_rows,
    elastic_deflection,
    flowing,
    joint_frames,
    limit_rows,
    rheology_rows,
)
from solver.model import Model
from solver.monitor import check_state
from solver.observe import relative_rotations
from solver.pgs import pgs_solve
from solver.reference import reference_solve
from solver.response import dense_system, regularize, row_response, world_inverse_inertia
from solver.rows import KEY_SHIFT, KIND_CONTACT, KIND_FRICTION, KIND_RHEOLOGY, Rows, concat
from solver.sleep import body_islands, settle, touch
from solver.stabilize import project_joints
from solver.state import State, StepInput, StepReport
from solver.substep import model_substeps, run_substeps
from solver.touch import POINTER_KEY_OFFSET, pointer_contacts


def build_rows(
    model: Model,
    state: State,
    body_rot: np.ndarray,
    vel_free: np.ndarray,
    inp: StepInput | None = None,
    asleep: np.ndarray | None = None,
) -> tuple[Rows, int, np.ndarray]:
    """The step's row table, its contact count, and the joint of each rheology row;
    ``asleep`` (nb,) bool: bodies whose island sleeps get no rows (solver.sleep)."""
    inp = inp or StepInput()
    h = model.options.h
    fr = joint_frames(model, state.body_pos, state.body_quat, body_rot)
    blocks = [anchor_rows(model, fr, h, state.body_omega)]
    rheo_joint = np.zeros(0, dtype=np.int64)
    if model.joint_rheology.any():
        block, rheo_joint = rheology_rows(model, state, fr, h)
        blocks.append(block)
    if model.has_limits:
        blocks.append(limit_rows(model, fr, h))
    ncontact = 0
    if model.has_collision:
        con = collide.collide(
            model.geometry, state.body_pos, state.body_quat, model.options.contact_margin,
            cull=model.options.cull_pairs, active=_awake_pairs(model, asleep),
        )  # fmt: skip
        ncontact = len(con.key)
        if ncontact:
            blocks.append(contact_rows(model, con, state.body_pos, vel_free))
    blocks.extend(_pointer_rows(model, state, inp, vel_free))
    rows = concat(blocks)
    if asleep is None or not asleep.any():
        return rows, ncontact, rheo_joint
    keep = _awake_rows(model, rows, asleep)
    rheo_joint = rheo_joint[keep[rows.kind == KIND_RHEOLOGY]]
    return _select(rows, keep), ncontact, rheo_joint


def _awake_pairs(model: Model, asleep: np.ndarray | None) -> np.ndarray | None:
    """(npair,) bool: shape pairs with a body that moves and is awake (None: all)."""
    if asleep is None or not asleep.any():
        return None
    g = model.geometry
    awake = np.append((model.body_inv_mass > 0.0) & ~asleep, False)  # index −1: static
    return awake[g.shape_body[g.pair_a]] | awake[g.shape_body[g.pair_b]]


def _awake_rows(model: Model, rows: Rows, asleep: np.ndarray) -> np.ndarray:
    """(n,) bool: rows with a movable side that is awake."""
    awake = np.append((model.body_inv_mass > 0.0) & ~asleep, False)
    return awake[rows.body_a] | awake[rows.body_b]


def _select(rows: Rows, keep: np.ndarray) -> Rows:
    """The rows ``keep`` (friction rows' normal indices renumbered)."""
    new_index = np.cumsum(keep) - 1
    fric = np.where(rows.fric_of >= 0, new_index[np.maximum(rows.fric_of, 0)], -1)
    fields = {f: getattr(rows, f)[keep] for f in Rows.__dataclass_fields__ if f != "fric_of"}
    return Rows(fric_of=fric[keep], **fields)


def _pointer_rows(model: Model, state: State, inp: StepInput, vel_free: np.ndarray) -> list[Rows]:
    """Grip coupling rows, or (free mode) the pointer sphere's contact rows."""
    ptr = inp.pointer
    if ptr is None:
        return []
    h = model.options.h
    if inp.coupling is not None:
        return [coupling_rows(state, ptr, inp.coupling, h)]
    if ptr.radius <= 0.0:
        return []
    con = pointer_contacts(model, state, ptr.pos - h * ptr.vel, ptr.radius)
    if len(con.key) == 0:
        return []
    return [contact_rows(model, con, state.body_pos, vel_free, velocity_a=ptr.vel)]


def warm_start(model: Model, state: State, rows: Rows) -> np.ndarray:
    """Last step's forces for rows with the same key, scaled by the warm-start factor."""
    opt = model.options
    lam = np.zeros(len(rows))
    if not opt.warm_start or len(state.warm_key) == 0:
        return lam
    at = np.searchsorted(state.warm_key, rows.key)
    at = np.minimum(at, len(state.warm_key) - 1)
    hit = state.warm_key[at] == rows.key
    lam[hit] = opt.warm_start_factor * state.warm_lam[at[hit]]
    return lam


def solve(model: Model, state: State, rows: Rows, resp: tuple, vel_free: np.ndarray) -> tuple:
    """(λ, velocities, iterations, residual, solver name) for the step's rows."""
    opt = model.options
    method = opt.method
    if method == "auto":
        method = "direct" if rows.bilateral else "hybrid"
    lam0 = warm_start(model, state, rows)
    if method == "direct":
        if not rows.bilateral:
            raise ValueError(
                "the direct solver handles two-sided rows only (no contacts or limits)"
            )
        lam, residual, ok = direct_solve(rows, resp, vel_free)
        if ok:
            return lam, _apply(rows, resp, vel_free, lam), 1, residual, "direct"
        lam0 = lam  # the active set did not settle: finish with PGS from there
    if method == "hybrid":
        lam, sweeps, residual = hybrid_solve(
            rows, resp, vel_free, lam0, opt.iterations, skip_dormant=opt.dormant_rows
        )
        return lam, _apply(rows, resp, vel_free, lam), sweeps, residual, "hybrid"
    if method == "reference":
        q, c = dense_system(rows, resp, vel_free)
        lam = reference_solve(q, c, rows.lo, rows.hi, rows.fric_of, rows.mu)
        return lam, _apply(rows, resp, vel_free, lam), 1, 0.0, "reference"
    lam, vel, sweeps, residual = pgs_solve(
        rows.body_a, rows.body_b, rows.jac_a, rows.jac_b, resp[0], resp[1], rows.lo, rows.hi,
        rows.comp, rows.bias, rows.fric_of, rows.mu, vel_free, lam0, opt.iterations, 1e-12,
    )  # fmt: skip
    return lam, vel, sweeps, residual, "pgs"


def _apply(rows: Rows, resp: tuple, vel_free: np.ndarray, lam: np.ndarray) -> np.ndarray:
    """vel_free plus the velocity response to the row forces."""
    vel = np.vstack((vel_free, np.zeros((1, 6))))
    np.add.at(vel, rows.body_a, resp[0] * lam[:, None])
    np.add.at(vel, rows.body_b, resp[1] * lam[:, None])
    return vel[:-1]


def step(model: Model, state: State, inp: StepInput | None = None) -> tuple[State, StepReport]:
    """Advance one step of size model.options.h (in equal substeps when the joints'
    geometric stiffness needs them: solver.substep)."""
    inp = inp or StepInput()
    body_rot = quat.matrix(state.body_quat)
    n = model_substeps(model, state)
    if n > 1:
        return run_substeps(model, state, inp, n, step)
    return _step_once(model, state, inp, body_rot)


def _step_once(
    model: Model, state: State, inp: StepInput, body_rot: np.ndarray
) -> tuple[State, StepReport]:
    h = model.options.h
    asleep, still, fresh = wake(model, state, inp)
    inv_i = world_inverse_inertia(model.body_inv_inertia, body_rot)
    vel_free = free_velocity(model, state, inp, inv_i)
    vel_free[asleep] = 0.0
    rows, ncontact, rheo_joint = build_rows(model, state, body_rot, vel_free, inp, asleep)
    resp = row_response(rows, model.body_inv_mass, inv_i, h)
    rows = regularize(rows, resp, model.options.regularization)
    try:
        lam, vel, iters, residual, used = solve(model, state, rows, resp, vel_free)
    except ValueError as exc:
        raise SimulationError(str(exc), state.step, state.time, None) from None
    check_state(model, state.step, state.time, state.body_pos, state.body_quat, vel)
    pos, q, omega = integrate_pose(model, state, vel, body_rot)
    pos[asleep], q[asleep], omega[asleep] = state.body_pos[asleep], state.body_quat[asleep], 0.0
    pos, q = project_joints(model, pos, q, asleep=asleep)
    check_state(model, state.step, state.time, pos, q, np.concatenate((vel[:, :3], omega), 1))
    rheo = _rheology_update(model, state, rows, vel, lam, rheo_joint, q)
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
    new = replace(
        state,
        time=state.time + h,
        step=state.step + 1,
        body_pos=pos,
        body_quat=q,
        body_vel=lin,
        body_omega=omega,
        warm_key=rows.key[order],
        warm_lam=lam[order],
        body_asleep=asleep,
        body_still=still,
        **rheo,
    )
    grip_force, grip_torque = coupling_wrench(rows, lam)
    return new, StepReport(
        len(rows), ncontact, iters, float(residual), used, grip_force, grip_torque,
        touch_force(rows, lam),
    )  # fmt: skip


def wake(model: Model, state: State, inp: StepInput) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(asleep, still, touched) (nb,) after waking the islands this step's input or a
    moving neighbour touches (solver.sleep.touch); all awake when sleeping is off."""
    nb, opt = model.nbody, model.options
    asleep, still = np.zeros(nb, dtype=bool), np.zeros(nb)
    fresh = np.zeros(nb, dtype=bool)
    if not opt.sleep:
        return asleep, still, fresh
    if len(state.body_asleep) == nb:
        asleep, still = state.body_asleep.copy(), state.body_still.copy()
    loaded = np.zeros(nb, dtype=bool)
    for load in (inp.body_force, inp.body_torque):
        if load is not None:
            loaded |= np.any(np.asarray(load) != 0.0, axis=1)
    ptr, cpl = inp.pointer, inp.coupling
    grip_body = cpl.body if (ptr is not None and cpl is not None) else -1
    pointer = np.zeros(4)
    if ptr is not None and cpl is None and ptr.radius > 0.0:
        pointer[:3], pointer[3] = ptr.pos - opt.h * ptr.vel, ptr.radius
    g = model.geometry
    centre, _ = collide.world_shapes(g, state.body_pos, state.body_quat)
    touch(
        body_islands(model), asleep, still, fresh, loaded, grip_body, pointer, centre,
        collide.shape_bounds(g), g.shape_body, g.pair_a, g.pair_b, opt.contact_margin,
        state.body_vel, state.body_omega, opt.sleep_speed, opt.sleep_spin,
    )  # fmt: skip
    return asleep, still, fresh


def touch_force(rows: Rows, lam: np.ndarray) -> np.ndarray:
    """Force (3,) the pointer sphere's contacts put on the bones (normal and friction)."""
    ident = rows.key & ((1 << KEY_SHIFT) - 1)
    sel = (rows.kind >= KIND_CONTACT) & (rows.kind <= KIND_FRICTION) & (ident >= POINTER_KEY_OFFSET)
    return rows.jac_b[sel, :3].T @ lam[sel]


def _rheology_update(
    model: Model, state: State, rows: Rows, vel: np.ndarray, lam: np.ndarray,
    rheo_joint: np.ndarray, body_quat: np.ndarray,
) -> dict:  # fmt: skip
    """q_sf, yield flags, anchors and torques after the solve (digest §4.4, yield §2.6)."""
    h = model.options.h
    nj = model.njoint
    sel = rows.kind == KIND_RHEOLOGY
    torque = np.zeros((nj, 3))
    w = np.zeros((nj, 3))
    if sel.any():
        vel_ext = np.vstack((vel, np.zeros((1, 6))))
        w_rows = np.einsum("ni,ni->n", rows.jac_a[sel], vel_ext[rows.body_a[sel]]) + np.einsum(
            "ni,ni->n", rows.jac_b[sel], vel_ext[rows.body_b[sel]]
        )
        j = rheo_joint[::3]
        torque[j] = lam[sel].reshape(-1, 3)
        w[j] = w_rows.reshape(-1, 3)
    alpha = h / (model.options.yield_filter_time + h)
    avg = state.joint_torque_avg + alpha * (np.linalg.norm(torque, axis=1) - state.joint_torque_avg)
    flow = flowing(model, state.joint_yielded) & model.joint_rheology
    q_sf = state.joint_q_sf.copy()
    if flow.any():
        dd = model.joint_dd[flow]
        q_sf[flow] = three_element_update(
            model.joint_kf[flow], model.joint_df[flow], dd, q_sf[flow], w[flow], h
        )
    can_yield = np.isfinite(model.joint_yield) & np.all(np.isfinite(model.joint_dd), axis=1)
    yielded = state.joint_yielded.copy()
    q_rel = relative_rotations(model, body_quat)
    anchor = state.joint_anchor.copy()
    unyield = can_yield & yielded & (avg < model.joint_yield)
    anchor[unyield] = quat.mul(quat.exp(-q_sf[unyield]), q_rel[unyield])
    yielded = np.where(can_yield, np.where(yielded, ~unyield, avg > model.joint_yield), False)
    elastic = ~flowing(model, yielded) & model.joint_rheology
    q_sf[elastic] = elastic_deflection(q_rel[elastic], anchor[elastic])
    return dict(
        joint_q_sf=q_sf,
        joint_yielded=yielded,
        joint_anchor=anchor,
        joint_torque_avg=avg,
        joint_torque=torque,
    )
