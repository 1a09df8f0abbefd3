"""All of a step's rows, in a fixed order: joints, contacts, the pointer's rows, pins."""

from __future__ import annotations

import numpy as np

from solver.collide import scene as collide
from solver.collide.pointer import pointer_contacts
from solver.model import Model
from solver.rows.contacts import contact_rows
from solver.rows.grip import coupling_rows
from solver.rows.joints import (
    anchor_rows,
    joint_frames,
    limit_rows,
    rheology_rows,
)
from solver.rows.pin import pin_rows
from solver.rows.table import KIND_RHEOLOGY, Rows, concat, take_rows
from solver.state import State, StepInput


def build_rows(
    model: Model,
    state: State,
    body_rot: np.ndarray,
    vel_free: np.ndarray,
    inp: StepInput | None = None,
    asleep: np.ndarray | None = None,
) -> tuple[Rows, int, np.ndarray]:
    """The step's row table, its contact count, and the joint of each rheology row;
    ``asleep`` (nb,) bool: bodies whose island sleeps get no rows (solver.advance.sleep)."""
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
    if inp.pins:
        blocks.append(_pin_rows(model, state, body_rot, inp.pins, asleep))
    rows = concat(blocks)
    if asleep is None or not asleep.any():
        return rows, ncontact, rheo_joint
    keep = _awake_rows(model, rows, asleep)
    rheo_joint = rheo_joint[keep[rows.kind == KIND_RHEOLOGY]]
    return take_rows(rows, keep), ncontact, rheo_joint


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


def _pin_rows(
    model: Model, state: State, body_rot: np.ndarray, pins: tuple, asleep: np.ndarray | None
) -> Rows:
    """The pins' rows (solver.rows.pin), for bodies that move and are awake."""
    movable = model.body_inv_mass > 0.0
    if asleep is not None:
        movable = movable & ~asleep
    o = model.options
    return pin_rows(pins, state.body_pos, state.body_quat, body_rot, state.body_omega, o.h,
                    o.joint_erp, movable)  # fmt: skip


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
