"""String geometry of a grip pose: lengths, encoder counts, the structure matrix, reachability.

Grip pose (p, R) in the device frame, R from the unit quaternion q (w, x, y, z).  String i:

    r_i = R a_i                    grip attachment relative to the grip centre
    d_i = m_i − (p + r_i),  l_i = |d_i|,  u_i = d_i / l_i      (unit direction grip → motor)
    w_i = r_i × u_i                moment direction

Structure matrix A (n×6), row i = [u_iᵀ, w_iᵀ].  Two readings of the same matrix:

- kinematics: a small motion (δp, δθ), δθ a rotation applied on the left (R ← Rot(δθ) R),
  changes the lengths by δl = −A (δp, δθ);
- statics: tensions t (t_i ≥ 0 pulls the grip toward m_i) put the wrench
  (f, τ) = Aᵀ t on the grip, τ about the grip centre p.

Encoders count changes from the calibration at home (p = 0, R = I):
counts c_i = round((l_i − l_i,home) / κ_i), and back l_i = l_i,home + κ_i c_i.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from puppetcli.spidar.errors import DeviceError
from puppetcli.spidar.presets import DevicePreset
from solver import quat

__all__ = [
    "StringState",
    "check_reachable",
    "counts_from_pose",
    "lengths_from_counts",
    "lengths_from_pose",
    "strings_at",
    "structure_matrix",
]

MIN_LENGTH = 1e-3  # m: a string shorter than this means the grip is at a pulley
ANGLE_MAX = math.pi / 2  # rad: the estimator's rotation clamp (Springhead's angleMax)


@dataclass(frozen=True)
class StringState:
    """The strings at one grip pose.

    attach (n,3) m: r_i = R a_i.  direction (n,3): u_i, grip → motor.  length (n,) m: l_i.
    moment (n,3) m: w_i = r_i × u_i.
    """

    attach: np.ndarray
    direction: np.ndarray
    length: np.ndarray
    moment: np.ndarray

    @property
    def structure(self) -> np.ndarray:
        """Structure matrix A (n,6), rows [u_i, w_i]."""
        return np.concatenate((self.direction, self.moment), axis=1)


def strings_at(preset: DevicePreset, pos: np.ndarray, q: np.ndarray) -> StringState:
    """Directions, lengths and moments of every string for one grip pose (p, q)."""
    p, q = np.asarray(pos, dtype=float), np.asarray(q, dtype=float)
    return StringState(*_strings(preset.motor_pos, preset.grip_attach, p, q))


@njit(cache=True)
def _strings(motor: np.ndarray, attach_local: np.ndarray, p: np.ndarray, q: np.ndarray):
    """(r, u, l, w) of the module docstring for one pose: compiled, since a replay or a live
    session asks once a physics step (numpy's dozen small calls cost ~60 µs)."""
    n = len(motor)
    attach, u, length, moment = np.empty((n, 3)), np.empty((n, 3)), np.empty(n), np.empty((n, 3))
    w, qv = q[0], q[1:]
    for i in range(n):
        a = attach_local[i]
        t = 2.0 * np.cross(qv, a)
        r = a + w * t + np.cross(qv, t)
        d = motor[i] - (p + r)
        length[i] = np.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
        attach[i], u[i] = r, d / length[i]
        moment[i] = np.cross(r, u[i])
    return attach, u, length, moment


def structure_matrix(preset: DevicePreset, pos: np.ndarray, q: np.ndarray) -> np.ndarray:
    """A (n,6) at the pose (p, q): rows [u_i, r_i × u_i]."""
    return strings_at(preset, pos, q).structure


def lengths_from_pose(preset: DevicePreset, pos: np.ndarray, q: np.ndarray) -> np.ndarray:
    """String lengths (…, n) m for poses pos (…, 3), q (…, 4) (broadcasting)."""
    pos = np.asarray(pos, dtype=float)[..., None, :]
    q = np.asarray(q, dtype=float)[..., None, :]
    attach = quat.rotate(q, preset.grip_attach)
    return np.linalg.norm(preset.motor_pos - (pos + attach), axis=-1)


def lengths_from_counts(preset: DevicePreset, counts: np.ndarray) -> np.ndarray:
    """Measured lengths l_i = l_i,home + κ_i c_i (…, n) m from encoder counts (…, n)."""
    return preset.home_lengths + preset.metres_per_count * np.asarray(counts, dtype=float)


def counts_from_pose(
    preset: DevicePreset, pos: np.ndarray, q: np.ndarray, check: bool = True
) -> np.ndarray:
    """Encoder counts (…, n) int64 the device reads at poses (…, 3), (…, 4).

    c_i = round((l_i − l_i,home)/κ_i): zero at home; quantisation |δl_i| ≤ |κ_i|/2.
    With ``check`` every pose must be reachable (``check_reachable``) or ``DeviceError``.
    """
    if check:
        check_reachable(preset, pos, q)
    change = lengths_from_pose(preset, pos, q) - preset.home_lengths
    return np.rint(change / preset.metres_per_count).astype(np.int64)


def _flat_poses(pos: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Poses broadcast together and flattened to (k,3), (k,4)."""
    pos = np.asarray(pos, dtype=float)
    q = np.asarray(q, dtype=float)
    batch = np.broadcast_shapes(pos.shape[:-1], q.shape[:-1])
    flat_pos = np.broadcast_to(pos, (*batch, 3)).reshape(-1, 3)
    return flat_pos, np.broadcast_to(q, (*batch, 4)).reshape(-1, 4)


def check_reachable(
    preset: DevicePreset,
    pos: np.ndarray,
    q: np.ndarray,
    min_length: float = MIN_LENGTH,
    angle_max: float | None = ANGLE_MAX,
) -> None:
    """Raise ``DeviceError`` unless every pose (…,3)/(…,4) is one the strings can hold.

    A pose is reachable when the grip centre and every attachment point p + R a_i lie
    inside the frame (the convex hull of the string exits), every string is at least
    ``min_length`` long (a string cannot have zero or negative length: the grip would be
    through a pulley) and the rotation from home is at most ``angle_max`` (the
    estimator clamps there, so a larger rotation would be recorded wrongly).
    The message names the first bad sample (flat index), the string and the amount.
    """
    flat_pos, flat_q = _flat_poses(pos, q)
    points = flat_pos[:, None, :] + quat.rotate(flat_q[:, None, :], preset.grip_attach)
    points = np.concatenate((flat_pos[:, None, :], points), axis=1)  # centre, then strings
    planes = preset.frame_planes
    outside = np.max(points @ planes[:, :3].T + planes[:, 3], axis=-1)  # > 0: outside
    length = np.linalg.norm(preset.motor_pos - points[:, 1:], axis=-1)
    angle = np.linalg.norm(quat.log(flat_q), axis=-1)
    limit = math.inf if angle_max is None else angle_max
    bad = np.any(outside > 0.0, axis=1) | np.any(length < min_length, axis=1) | (angle > limit)
    if not np.any(bad):
        return
    i = int(np.argmax(bad))
    where = f"{preset.name}: pose {i}" if len(flat_pos) > 1 else f"{preset.name}: pose"
    where += f" (p = {_fmt(flat_pos[i])} m)"
    if np.any(outside[i] > 0.0):
        k = int(np.argmax(outside[i]))
        what = "the grip centre" if k == 0 else f"string {k - 1}'s attachment"
        raise DeviceError(f"{where}: {what} is {outside[i, k] * 1e3:.3g} mm outside the frame")
    if np.any(length[i] < min_length):
        k = int(np.argmin(length[i]))
        raise DeviceError(
            f"{where}: string {k} would be {length[i, k] * 1e3:.3g} mm long "
            f"(expected at least {min_length * 1e3:.3g} mm)"
        )
    raise DeviceError(
        f"{where}: grip rotated {math.degrees(angle[i]):.4g}° from home "
        f"(expected at most {math.degrees(limit):.4g}°, the estimator's clamp)"
    )


def _fmt(v: np.ndarray) -> str:
    """A short vector text."""
    return "(" + ", ".join(f"{x:.4g}" for x in v) + ")"
