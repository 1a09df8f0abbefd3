"""The haptic pointer's motion: minimum-jerk moves and rotations, sampled per step.

A move from p0 to p1 over T follows p(t) = p0 + (p1 − p0)·s(t/T) with the
minimum-jerk profile s(τ) = 10τ³ − 15τ⁴ + 6τ⁵ (zero velocity and acceleration at
both ends).  A rotation by angle θ about a world axis n through the pointer
follows q(t) = exp(n·θ·s(t/T)) ⊗ q0; about a pivot c instead (an arc), the position
turns with it: p(t) = c + exp(n·θ·s(t/T))·(p0 − c).  The velocity handed to the solver for a
step is the exact mean over that step: (pose_end − pose_start)/h.

Workspace mapping (device → world): world = offset + scale · device.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from solver import quat, quat1
from solver.rows.grip import Pointer


def min_jerk(tau):
    """s(τ) = 10τ³ − 15τ⁴ + 6τ⁵ with τ clamped to [0, 1], of a float or elementwise of an
    array (the same floats either way)."""
    t = np.clip(tau, 0.0, 1.0)
    return t * t * t * (10.0 + t * (-15.0 + 6.0 * t))


@dataclass(frozen=True)
class Motion:
    """A pointer motion from (pos0, quat0) starting at t0 over ``duration``: a move by
    ``delta`` and a turn by ``rotvec`` about the pointer, or, with ``pivot``, about that
    world point (an arc: the position turns about the pivot too)."""

    t0: float
    duration: float
    pos0: np.ndarray
    quat0: np.ndarray
    delta: np.ndarray  # (3,) displacement
    rotvec: np.ndarray  # (3,) world rotation vector
    pivot: np.ndarray | None = None  # (3,) world point the turn is about; None: the pointer

    def pose(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """(position, quaternion) at time t."""
        pos, q = self.poses(np.array([t]))
        return pos[0], q[0]

    def poses(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(positions (n,3), quaternions (n,4)) at each of ``times``."""
        if self.duration > 0.0:
            s = min_jerk((times - self.t0) / self.duration)
        else:
            s = np.ones(len(times))
        s = s[:, None]
        turn = quat.exp(s * self.rotvec)
        pos = self.pos0 if self.pivot is None else (
            self.pivot + quat.rotate(turn, self.pos0 - self.pivot))  # fmt: skip
        return pos + s * self.delta, quat.mul(turn, self.quat0)


def still(pos: np.ndarray, q: np.ndarray) -> Motion:
    """The pointer at rest."""
    return Motion(0.0, 0.0, pos, q, np.zeros(3), np.zeros(3))


def pointer_over_step(motion: Motion, t: float, h: float, radius: float) -> Pointer:
    """The solver's Pointer for the step [t, t + h]: pose at its end, mean velocity over it."""
    p0, q0 = motion.pose(t)
    p1, q1 = motion.pose(t + h)
    turn = quat1.log(quat1.mul(tuple(q1.tolist()), quat1.conj(tuple(q0.tolist()))))
    return Pointer(p1, q1, (p1 - p0) / h, np.array(turn) / h, radius)


def pointer_path(motion, times: np.ndarray, h: float) -> tuple[np.ndarray, tuple]:
    """The pointer over the steps between consecutive ``times`` (t_k, t_k + h), all at
    once: (position (n+1,3) at every time, the path (position (n,3) and quaternion (n,4)
    at each step's end, mean velocity (n,3) and angular velocity (n,3) over it)).  The
    path is ``pointer_over_step``'s values for each step, the same floats; ``motion``
    is anything with ``poses(times)`` (a Motion, a recorded track)."""
    pos, q = motion.poses(times)
    turn = quat.log(quat.mul(q[1:], quat.conj(q[:-1])))
    return pos, (pos[1:], q[1:], (pos[1:] - pos[:-1]) / h, turn / h)


def device_from_world(pos: np.ndarray, offset: np.ndarray, scale: float) -> np.ndarray:
    """Device coordinates of a world position (inverse of world = offset + scale·device)."""
    return (pos - offset) / scale
