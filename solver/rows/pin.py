"""Pins: a point of a bone (3 rows), or the whole bone (6 rows), held where it was pinned.

A pin is an input of the step (``StepInput.pins``), like the grip: the caller holds it.
Position rows (world axes e_k), with r = R_b p the pinned point p (bone frame, m) from
the bone's centre of mass and t the pin's target (world, m):

    C = x_b + r − t,   w_k = e_k·(v_b + ω_b × r),
    bias_k = (erp·C_k + N_k)/h,   N = exp(hω) r − r − h ω × r,

the ball joints' anchor rows with the world as the other side (solver.rows.joints): a
hard row (compliance only the solver's regularisation) whose bias removes the fraction
``joint_erp`` of the drift every step, with the rotating point's arc term, so a pinned
point does not creep.  Orientation rows (``orient``): C = log(q_b ⊗ q_t⁻¹) (world),
w_k = e_k·ω_b, bias_k = erp·C_k/h.  λ_k is the force (N) or torque (N·m) the pin puts on
the bone along e_k; the force acts at the pinned point.

Limits are per row (a box, like the grip's): |λ_k| ≤ force_limit on each world axis
(torque_limit for orientation rows), so the force a pin can carry is ≤ force_limit along
an axis and ≤ √3·force_limit in a diagonal direction.  A row whose force reaches its
limit ends the step *at* the limit and the point moves: the pin **slips**.  The step
reports it (StepReport.pin_slip); the caller then moves the pin's target to where the
point (and bone) now is (``retarget``), so the pin holds there afterwards and never
snaps back.

Row keys: 8·bone + slot (0–2 position, 3–5 orientation), one pin per bone: stable
while the pin exists, so its force is warm-started like every other row.  Bones that
cannot move or whose island sleeps get no pin rows (their force reads 0).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from solver import quat
from solver.rows.joints import arc_offset
from solver.rows.table import (
    KEY_SHIFT,
    KIND_PIN,
    Rows,
    angular_jacobians,
    concat,
    make_rows,
    point_jacobians,
)
from solver.state import State, StepReport

SLOTS = 8
"""Row keys per pinned bone (six used)."""


@dataclass(frozen=True)
class Pin:
    """One pin: bone (body index); point (3,) m in the bone's frame, from its centre of
    mass; target (3,) m, world: where the point is held; target_quat (4,) (w,x,y,z): the
    bone's held orientation (read when ``orient``); force_limit N, torque_limit N·m per
    row (inf: no limit)."""

    bone: int
    point: np.ndarray
    target: np.ndarray
    target_quat: np.ndarray
    orient: bool = False
    force_limit: float = np.inf
    torque_limit: float = np.inf


def make_pin(
    state: State,
    bone: int,
    point: np.ndarray | None = None,
    orient: bool = False,
    force_limit: float = np.inf,
    torque_limit: float = np.inf,
) -> Pin:
    """A pin holding ``point`` (bone frame from the centre of mass; None: the centre of
    mass) of ``bone`` where it is in ``state`` (no jump at pinning)."""
    p = np.zeros(3) if point is None else np.asarray(point, dtype=float)
    q = state.body_quat[bone]
    target = state.body_pos[bone] + quat.rotate(q, p)
    return Pin(bone, p, target, q.copy(), bool(orient), float(force_limit), float(torque_limit))


def pin_rows(
    pins: tuple, body_pos: np.ndarray, body_quat: np.ndarray, body_rot: np.ndarray,
    omega: np.ndarray, h: float, erp: float, movable: np.ndarray,
) -> Rows:  # fmt: skip
    """The rows of ``pins`` (module docstring), in order; movable (nb,) bool: bodies that
    move and are awake (the others get no rows)."""
    blocks = []
    axes = np.eye(3)
    for pin in pins:
        b = pin.bone
        if not movable[b]:
            continue
        r = body_rot[b] @ pin.point
        gap = erp * (body_pos[b] + r - pin.target) + arc_offset(omega[b], r, h)
        jac_a, jac_b = point_jacobians(axes, np.zeros((3, 3)), np.tile(r, (3, 1)))
        lim = pin.force_limit
        blocks.append(make_rows(KIND_PIN, SLOTS * b + np.arange(3), -1, b, jac_a, jac_b,
                                lo=-lim, hi=lim, bias=gap / h))  # fmt: skip
        if pin.orient:
            turn = quat.log(quat.mul(body_quat[b], quat.conj(pin.target_quat)))
            jac_a, jac_b = angular_jacobians(axes)
            lim = pin.torque_limit
            blocks.append(make_rows(KIND_PIN, SLOTS * b + np.arange(3, 6), -1, b, jac_a, jac_b,
                                    lo=-lim, hi=lim, bias=erp * turn / h))  # fmt: skip
    return concat(blocks)


def pin_keys(pins: tuple) -> np.ndarray:
    """(npin, 6) the row keys of each pin's six slots."""
    bones = np.array([p.bone for p in pins], dtype=np.int64).reshape(-1, 1)
    return (np.int64(KIND_PIN) << KEY_SHIFT) + SLOTS * bones + np.arange(6)


def pin_wrench(pins: tuple, warm_key: np.ndarray, warm_lam: np.ndarray) -> tuple:
    """(force (npin,3) N, torque (npin,3) N·m, slip (npin,) bool) of a step's pins from its
    row forces by key (State.warm_key, sorted, and warm_lam): the wrench each pin put on
    its bone (force at the pinned point) and whether a row of it reached its limit."""
    keys = pin_keys(pins)
    lam = np.zeros(keys.shape)
    if len(warm_key):
        at = np.minimum(np.searchsorted(warm_key, keys), len(warm_key) - 1)
        hit = warm_key[at] == keys
        lam[hit] = warm_lam[at[hit]]
    limit = np.array([[p.force_limit] * 3 + [p.torque_limit] * 3 for p in pins]).reshape(-1, 6)
    slip = np.any(np.isfinite(limit) & (np.abs(lam) >= limit), axis=1)
    return lam[:, :3], lam[:, 3:], slip


def retarget(pins: tuple, state: State, slip: np.ndarray) -> tuple:
    """``pins`` with each slipped pin's target moved to where its point (and bone) is in
    ``state``: a pin that slipped holds from there on and never pulls back."""
    if not np.any(slip):
        return pins
    out = []
    for pin, slipped in zip(pins, slip, strict=True):
        if slipped:
            moved = make_pin(state, pin.bone, pin.point, pin.orient)
            pin = replace(pin, target=moved.target, target_quat=moved.target_quat)
        out.append(pin)
    return tuple(out)


def with_pins(report: StepReport, pins: tuple, state: State) -> StepReport:
    """``report`` with the wrench and slip of ``pins`` read from the step's ``state``'s row
    forces (unchanged without pins)."""
    if not pins:
        return report
    force, torque, slip = pin_wrench(pins, state.warm_key, state.warm_lam)
    return replace(report, pin_force=force, pin_torque=torque, pin_slip=slip)
