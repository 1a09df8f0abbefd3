"""The live device: the grip pose per 1 kHz tick, from the page's target pose.

The page sends target poses (world) at its frame rate, ~60 Hz.  A real grip moves
continuously, so each device tick moves the pose towards the target by a one-pole
smoothing with time constant ``SMOOTHING`` (position: p ← p + α(target − p); orientation:
the same fraction of the rotation, α = 1 − exp(−tick/τ)), except when the pointer
*jumps* (a click grips a bone at the clicked point: the pointer is put there).

Each tick is recorded as the session's ``/spidar/pose`` (device frame) and appended to a
``LiveTrack``, the growing twin of a replay's ``DeviceTrack``: the world pose of a tick
is computed from the recorded device pose by the same operations the session reader and
``Workspace.world_from_device`` apply, so a replay sees exactly the poses the live run
used (``solver.quat1``: numpy's operations on one pose, in Python floats).
"""

from __future__ import annotations

import math

import numpy as np

from puppetcli.mcap.replay import TrackLookup
from puppetcli.mcap.session import TICK, Workspace
from solver import quat1

__all__ = ["SMOOTHING", "LiveTrack", "PointerFilter", "device_from_world"]

SMOOTHING = 0.012  # s: time constant of the tick-by-tick approach to the page's target


class LiveTrack(TrackLookup):
    """Per-tick poses appended as they are made; the arrays are views of what is filled."""

    def __init__(self, workspace: Workspace, capacity: int = 4096) -> None:
        self.workspace = workspace
        self._n = 0
        self._time = np.zeros(capacity)
        self._dev_pos, self._dev_quat = np.zeros((capacity, 3)), np.zeros((capacity, 4))
        self._pos, self._quat = np.zeros((capacity, 3)), np.zeros((capacity, 4))

    def __len__(self) -> int:
        return self._n

    def append(self, t: float, device_pos: tuple, device_quat: tuple) -> None:
        """Add the tick at time ``t`` with its recorded device pose (tuples of floats)."""
        if self._n == len(self._time):
            self._grow()
        k = self._n
        q = quat1.normalize(device_quat)  # as the session reader does
        world_pos, world_quat = _world_from_device(self.workspace, device_pos, q)
        self._time[k], self._dev_pos[k], self._dev_quat[k] = t, device_pos, q
        self._pos[k], self._quat[k] = world_pos, world_quat
        self._n += 1

    def _grow(self) -> None:
        for name in ("_time", "_dev_pos", "_dev_quat", "_pos", "_quat"):
            old = getattr(self, name)
            new = np.zeros((2 * len(old), *old.shape[1:]))
            new[: len(old)] = old
            setattr(self, name, new)

    @property
    def time(self) -> np.ndarray:
        return self._time[: self._n]

    @property
    def device_pos(self) -> np.ndarray:
        return self._dev_pos[: self._n]

    @property
    def device_quat(self) -> np.ndarray:
        return self._dev_quat[: self._n]

    @property
    def world_pos(self) -> np.ndarray:
        return self._pos[: self._n]

    @property
    def world_quat(self) -> np.ndarray:
        return self._quat[: self._n]


class PointerFilter:
    """The grip's world pose, moved towards the target once per tick (module docstring)."""

    def __init__(self, pos, q, tau: float = SMOOTHING) -> None:
        self.pos, self.quat = tuple(map(float, pos)), tuple(map(float, q))
        self.alpha = 1.0 - math.exp(-TICK / tau)

    def tick(self, target_pos, target_quat) -> None:
        """One tick towards the target."""
        a = self.alpha
        self.pos = tuple(p + a * (g - p) for p, g in zip(self.pos, target_pos, strict=True))
        self.quat = _slerp(self.quat, target_quat, a)

    def jump(self, pos, q) -> None:
        """Be at ``pos``, ``q`` now."""
        self.pos, self.quat = tuple(map(float, pos)), tuple(map(float, q))


def _slerp(q0: tuple, q1: tuple, a: float) -> tuple:
    """The rotation a of the way from q0 to q1 (shortest arc), normalised."""
    d = quat1.mul(q1, quat1.conj(q0))
    if d[0] < 0.0:
        d = tuple(-c for c in d)
    s = math.sqrt(d[1] * d[1] + d[2] * d[2] + d[3] * d[3])
    if s < 1e-12:
        return quat1.normalize(q1)
    half = a * math.atan2(s, d[0])
    k = math.sin(half) / s
    return quat1.normalize(quat1.mul((math.cos(half), k * d[1], k * d[2], k * d[3]), q0))


def device_from_world(ws: Workspace, pos: tuple, q: tuple) -> tuple[tuple, tuple]:
    """``Workspace.device_from_world`` of one pose."""
    r_inv = quat1.conj(tuple(map(float, ws.orientation)))
    off, scale = ws.offset, float(ws.scale)
    device = quat1.rotate(r_inv, tuple((pos[i] - float(off[i])) / scale for i in range(3)))
    return device, quat1.mul(quat1.mul(r_inv, q), tuple(map(float, ws.orientation)))


def _world_from_device(ws: Workspace, pos: tuple, q: tuple) -> tuple[tuple, tuple]:
    """``Workspace.world_from_device`` of one pose."""
    r = tuple(map(float, ws.orientation))
    moved = quat1.rotate(r, pos)
    world = tuple(float(ws.offset[i]) + float(ws.scale) * moved[i] for i in range(3))
    return world, quat1.mul(quat1.mul(r, q), quat1.conj(r))
