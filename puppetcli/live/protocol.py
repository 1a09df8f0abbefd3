"""The page ↔ server messages of ``puppetcli live`` (JSON text over a WebSocket).

Every message from a page is untrusted: ``parse`` accepts only the documented shapes
(docs/live.md, "Protocol"), with finite numbers in sane ranges, known bone names and short
labels, and raises ``Rejected`` (one line) for anything else, so nothing malformed, NaN or
absurd reaches the simulation.  ``clamp_target`` keeps the pointer where the device can be:
inside the workspace ball and within the estimator's rotation limit.

``frame`` builds the server's per-display-frame message from the live recording.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from puppetcli.live import recording as rec
from puppetcli.live.clock import RealTimeClock
from puppetcli.spidar.strings import ANGLE_MAX
from solver import quat

__all__ = [
    "LABEL_MAX",
    "MAX_MESSAGE",
    "Pause",
    "Ping",
    "PointerTarget",
    "PositionOnly",
    "Rejected",
    "Stop",
    "clamp_target",
    "frame",
    "parse",
]

MAX_MESSAGE = 4096  # bytes: the largest message a page may send
LABEL_MAX = 64  # characters of a key label
COORD_MAX = 1e3  # m: larger coordinates are not a pose
SEQ_MAX = 2**53


class Rejected(ValueError):
    """A page message that is not one of the protocol's (the text says why, one line)."""


@dataclass(frozen=True)
class PointerTarget:
    pos: tuple[float, float, float]
    quat: tuple[float, float, float, float]


@dataclass(frozen=True)
class PositionOnly:
    on: bool


@dataclass(frozen=True)
class Pause:
    on: bool


@dataclass(frozen=True)
class Stop:
    pass


@dataclass(frozen=True)
class Ping:
    t: float


def _no_constant(name: str) -> Any:
    raise Rejected(f"expected finite numbers, got {name}")


def _number(msg: dict, key: str, limit: float = COORD_MAX) -> float:
    v = msg.get(key)
    if isinstance(v, bool) or not isinstance(v, int | float) or not abs(v) <= limit:
        raise Rejected(f"{key}: expected a number within ±{limit:g}, got {v!r:.40}")
    return float(v)


def _vector(msg: dict, key: str, n: int) -> tuple[float, ...]:
    v = msg.get(key)
    if not isinstance(v, list) or len(v) != n:
        raise Rejected(f"{key}: expected {n} numbers, got {v!r:.60}")
    return tuple(_number({key: x}, key) for x in v)


def _flag(msg: dict, key: str) -> bool:
    v = msg.get(key)
    if not isinstance(v, bool):
        raise Rejected(f"{key}: expected true or false, got {v!r:.40}")
    return v


def _unit(q: tuple[float, ...]) -> tuple[float, ...]:
    n = math.sqrt(sum(c * c for c in q))
    if not 0.5 <= n <= 2.0:
        raise Rejected(f"quat: expected a unit quaternion (w, x, y, z), got norm {n:.3g}")
    return tuple(c / n for c in q)


def _label(msg: dict) -> str | None:
    v = msg.get("label")
    if v is None or v == "":
        return None
    if not isinstance(v, str) or len(v) > LABEL_MAX or not v.isprintable():
        raise Rejected(f"label: expected printable text of at most {LABEL_MAX} characters")
    return v.strip() or None


def _grip(msg: dict, bones: list[str]) -> rec.Grip:
    only = None if msg.get("position_only") is None else _flag(msg, "position_only")
    if "bone" not in msg:
        return rec.Grip(position_only=only)
    bone = msg["bone"]
    if bone not in bones:
        raise Rejected(f"bone: expected a bone of the rig, got {bone!r:.40}")
    return rec.Grip(bone, np.array(_vector(msg, "point", 3)), only)


def _bone(msg: dict, bones: list[str]) -> str:
    bone = msg.get("bone")
    if bone not in bones:
        raise Rejected(f"bone: expected a bone of the rig, got {bone!r:.40}")
    return bone


def _pin(msg: dict, bones: list[str]) -> rec.Pin:
    orient = False if msg.get("orient") is None else _flag(msg, "orient")
    return rec.Pin(_bone(msg, bones), np.array(_vector(msg, "point", 3)), orient)


def _unpin(msg: dict, bones: list[str]) -> rec.Unpin:
    return rec.Unpin(None if msg.get("bone") is None else _bone(msg, bones))


_PARSERS = {
    "pointer": lambda m, b: PointerTarget(_vector(m, "pos", 3), _unit(_vector(m, "quat", 4))),
    "grip": _grip,
    "release": lambda m, b: rec.Release(),
    "touch": lambda m, b: rec.Touch(_flag(m, "on")),
    "position_only": lambda m, b: PositionOnly(_flag(m, "on")),
    "key": lambda m, b: rec.Key(_label(m)),
    "undo": lambda m, b: rec.Undo(),
    "pin": _pin,
    "unpin": _unpin,
    "pause": lambda m, b: Pause(_flag(m, "on")),
    "stop": lambda m, b: Stop(),
    "ping": lambda m, b: Ping(_number(m, "t", 1e15)),
}


def parse(text: str | bytes, bones: list[str]) -> tuple[int | None, object]:
    """(seq or None, the command) of one page message; ``Rejected`` for anything else."""
    if len(text) > MAX_MESSAGE:
        raise Rejected(f"expected a message of at most {MAX_MESSAGE} bytes, got {len(text)}")
    try:
        msg = json.loads(text, parse_constant=_no_constant)
    except (ValueError, RecursionError) as exc:
        if isinstance(exc, Rejected):
            raise
        raise Rejected("expected a JSON object, got text that is not JSON") from None
    if not isinstance(msg, dict) or msg.get("type") not in _PARSERS:
        kind = msg.get("type") if isinstance(msg, dict) else type(msg).__name__
        raise Rejected(f"type: expected one of {', '.join(_PARSERS)}, got {kind!r:.40}")
    seq = msg.get("seq")
    if seq is not None and (isinstance(seq, bool) or not isinstance(seq, int) or not
                            0 <= seq < SEQ_MAX):  # fmt: skip
        raise Rejected(f"seq: expected a non-negative integer, got {seq!r:.40}")
    return seq, _PARSERS[msg["type"]](msg, bones)


def clamp_target(
    target: PointerTarget, centre: np.ndarray, radius: float, orientation: np.ndarray
) -> PointerTarget:
    """The target moved into the workspace ball and its rotation from the device's home
    (the workspace ``orientation``) limited to the estimator's ``ANGLE_MAX``."""
    pos = np.array(target.pos)
    off = pos - centre
    dist = float(np.linalg.norm(off))
    if dist > radius:
        pos = centre + off * (radius / dist)
    q = np.array(target.quat)
    home = quat.mul(quat.mul(quat.conj(orientation), q), orientation)
    turn = quat.log(home)
    angle = float(np.linalg.norm(turn))
    if angle > ANGLE_MAX:
        limited = quat.exp(turn * (ANGLE_MAX / angle))
        q = quat.mul(quat.mul(orientation, limited), quat.conj(orientation))
    return PointerTarget(tuple(pos.tolist()), tuple(q.tolist()))


def _floats(a: np.ndarray) -> list[float]:
    return np.asarray(a, float).ravel().tolist()


def frame(live: rec.LiveRecording, clock: RealTimeClock, seq: int, ack: int, rejected: int):
    """The per-display-frame message (docs/live.md, "Protocol")."""
    s, tap, c = live.runner.state, live.tap, live.runner.coupling
    grip = None
    if c is not None:
        point = s.body_pos[c.body] + quat.rotate(s.body_quat[c.body], c.anchor)
        grip = {"bone": live.gripping, "point": _floats(point), "position_only": c.position_only}
    report = tap.report
    stats = {
        "rtf": clock.rtf, "headroom": min(clock.headroom, 1e6),
        "step_us": clock.step_time * 1e6, "steps_per_s": clock.rtf / live.model.options.h,
        "behind": clock.behind, "rejected": rejected,
        "rows": 0 if report is None else report.rows,
        "contacts": 0 if report is None else report.contacts,
        "iterations": 0 if report is None else report.iterations,
        "solver": "" if report is None else report.solver,
    }  # fmt: skip
    return {
        "type": "frame", "seq": seq, "t": round(s.time, 9),
        "body_pos": _floats(s.body_pos), "body_quat": _floats(s.body_quat),
        "pointer": {"pos": list(live.filter.pos), "quat": list(live.filter.quat)},
        "target": {"pos": list(live.target[0]), "quat": list(live.target[1])},
        "grip": grip, "touch": live.touch, "position_only": live.position_only,
        "paused": clock.paused,
        "wrench": {
            "force": _floats(tap.displayed[0]), "torque": _floats(tap.displayed[1]),
            "requested_force": _floats(tap.requested[0]),
            "requested_torque": _floats(tap.requested[1]),
        },
        "pins": _pins(live), "stats": stats, "ack": ack,
    }  # fmt: skip


def _pins(live: rec.LiveRecording) -> list[dict]:
    """The pins held: bone, where the point is held (m), orient, the force on the bone (N)."""
    board, report = live.runner.board, live.tap.report
    forces = report.pin_force if report is not None else ()
    if len(forces) != len(board.pins):
        forces = np.zeros((len(board.pins), 3))
    return [
        {"bone": name, "target": _floats(pin.target), "orient": pin.orient,
         "force": _floats(force)}
        for name, pin, force in zip(board.names, board.pins, forces, strict=True)
    ]  # fmt: skip
