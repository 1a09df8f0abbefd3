"""Simulation state and step input: everything that changes during a run."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from solver import quat
from solver.model import Model


@dataclass(frozen=True)
class State:
    """The state at one instant.  ``step()`` returns a new one; a keyframe is a kept State.

    time: s.  step: number of steps taken.
    body_pos (nb,3) m, centre of mass; body_quat (nb,4) (w,x,y,z) body → world;
    body_vel (nb,3) m/s; body_omega (nb,3) rad/s, world frame.
    joint_q_sf (nj,3) rad: elastic (Voigt) part of each joint's deflection, per
        parent-frame axis; in the elastic (unyielded) phase it equals the
        deflection from ``joint_anchor``.
    joint_yielded (nj,) bool: the joint is flowing (three-element rows).
    joint_anchor (nj,4): rest orientation (parent frame) the elastic phase springs
        back to; re-anchored at every un-yield.
    joint_torque_avg (nj,) N·m: low-passed norm of the rheology torque (yield test).
    joint_torque (nj,3) N·m: rheology row forces λ_s of the last step.
    warm_key (n,) int64 sorted, warm_lam (n,): row forces of the last step by row key.
    body_asleep (nb,) bool: the body's island sleeps (solver.advance.sleep); body_still (nb,) s:
        how long its island has been at rest.  Empty arrays mean all awake.
    prev_pos (nb,3), prev_quat (nb,4), prev_vel (nb,3), prev_omega (nb,3), prev_q_sf
        (nj,3): the previous step's values, for the second-order step
        (solver.advance.bdf2); prev_h (s): that step's length (0: no history, the next
        step starts afresh); prev_mark: the fingerprint of the state they lead to (a
        state changed after its step no longer matches it); prev_load: that step's
        input's (a step whose loads, grip or pointer mode differ starts afresh).  Empty
        under the paper's integrator.
    """

    time: float
    step: int
    body_pos: np.ndarray
    body_quat: np.ndarray
    body_vel: np.ndarray
    body_omega: np.ndarray
    joint_q_sf: np.ndarray
    joint_yielded: np.ndarray
    joint_anchor: np.ndarray
    joint_torque_avg: np.ndarray
    joint_torque: np.ndarray
    warm_key: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    warm_lam: np.ndarray = field(default_factory=lambda: np.zeros(0))
    body_asleep: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    body_still: np.ndarray = field(default_factory=lambda: np.zeros(0))
    prev_pos: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    prev_quat: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    prev_vel: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    prev_omega: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    prev_q_sf: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    prev_h: float = 0.0
    prev_mark: float = 0.0
    prev_load: float = 0.0


@dataclass(frozen=True)
class StepInput:
    """External input for one step, constant over the step.

    body_force (nb,3) N and body_torque (nb,3) N·m, world frame, about each
    body's centre of mass.  ``None`` = no external load.
    pointer: the haptic pointer (solver.rows.grip.Pointer) or None; coupling: the grip
    (solver.rows.grip.Coupling) or None.  Without a coupling, a pointer with a radius
    touches the bones (free mode).  pins: a tuple of solver.rows.pin.Pin, at most one per
    bone (empty: none, and no cost).
    """

    body_force: np.ndarray | None = None
    body_torque: np.ndarray | None = None
    pointer: Any = None
    coupling: Any = None
    pins: tuple = ()


@dataclass(frozen=True)
class StepReport:
    """What one step did, for traces and benchmarks.

    grip_force (3,) N, grip_torque (3,) N·m: the coupling's wrench on the gripped
    bone (torque about the grip point); touch_force (3,) N: the pointer's contact
    force on the bones in free mode.  The user's hand feels their opposite.
    substeps: how many parts the step was taken in: equal substeps when its joints'
    tension needs them (solver.advance.substep), three for a bdf2 restart
    (solver.advance.bdf2_kernel.RESTART); with more than one, rows and contacts are the
    last part's, iterations their sum, the residual their worst and the wrenches their
    mean.
    pin_force (npin,3) N, pin_torque (npin,3) N·m: the wrench each of the input's pins put
    on its bone (force at the pinned point; with substeps, the last substep's); pin_slip
    (npin,) bool: a row of the pin reached its limit (solver.rows.pin.retarget).
    """

    rows: int
    contacts: int
    iterations: int
    residual: float
    solver: str
    grip_force: np.ndarray = field(default_factory=lambda: np.zeros(3))
    grip_torque: np.ndarray = field(default_factory=lambda: np.zeros(3))
    touch_force: np.ndarray = field(default_factory=lambda: np.zeros(3))
    substeps: int = 1
    pin_force: np.ndarray = field(default_factory=lambda: NO_PINS)
    pin_torque: np.ndarray = field(default_factory=lambda: NO_PINS)
    pin_slip: np.ndarray = field(default_factory=lambda: NO_SLIP)


NO_PINS = np.zeros((0, 3))
NO_PINS.flags.writeable = False
NO_SLIP = np.zeros(0, dtype=bool)
NO_SLIP.flags.writeable = False


def initial_state(model: Model) -> State:
    """The rest pose, at rest."""
    nb, nj = model.nbody, model.njoint
    return State(
        time=0.0,
        step=0,
        body_pos=model.body_pos0.copy(),
        body_quat=model.body_quat0.copy(),
        body_vel=np.zeros((nb, 3)),
        body_omega=np.zeros((nb, 3)),
        joint_q_sf=np.zeros((nj, 3)),
        joint_yielded=np.zeros(nj, dtype=bool),
        joint_anchor=np.tile(quat.IDENTITY, (nj, 1)),
        joint_torque_avg=np.zeros(nj),
        joint_torque=np.zeros((nj, 3)),
        body_asleep=np.zeros(nb, dtype=bool),
        body_still=np.zeros(nb),
    )
