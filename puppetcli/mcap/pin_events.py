"""Pins in sessions (format 3, docs/sessions.md): a ``pin`` button on ``/spidar/buttons``.

    {"button": "pin", "state": "down", "bone": "head", "point": [0, 0.1, 0],
     "orient": true, "force_limit": 200.0, "torque_limit": 20.0}      pins the bone
    {"button": "pin", "state": "up", "bone": "head"}                   unpins it
    {"button": "pin", "state": "up"}                                   unpins every bone

``point`` (m, from the bone's head in its rest frame, as a grip's) and the limits (N, N·m,
finite and > 0) are optional, as in a script's ``pin`` (puppetcli.script.pins).  Replayed,
they become the script's own actions; a pin event that cannot be one (a bone pinned twice,
an unpin of a bone that is not pinned, a bad limit) is one ``SessionError`` line.
"""

from __future__ import annotations

import math

import numpy as np

from puppetcli.errors import SessionError, shown
from puppetcli.mcap.session import Event, Session
from puppetcli.script.actions import frozen_vector
from puppetcli.script.pins import Pin, Unpin
from puppetcli.yamldoc import did_you_mean
from solver.model import Model

LIMITS = ("force_limit", "torque_limit")


def pin_button(bone: str | None, down: bool, point=None, orient: bool = False,
               limits: dict | None = None) -> dict:  # fmt: skip
    """The ``/spidar/buttons`` fields of a pin (down) or an unpin (up; bone None: all)."""
    fields: dict = {"button": "pin", "state": "down" if down else "up"}
    if bone is not None:
        fields["bone"] = bone
    if not down:
        return fields
    if point is not None:
        fields["point"] = [float(x) for x in point]
    fields["orient"] = bool(orient)
    for key, value in (limits or {}).items():
        if math.isfinite(value):
            fields[key] = float(value)
    return fields


def pin_action(event: Event, session: Session, model: Model, pinned: set) -> Pin | Unpin:
    """The script action of a pin button event; ``pinned``: the bones pinned so far
    (updated)."""
    m, where = event.message, f"{session.source}: {event.topic}[{event.index}]"
    line = int(m.get("line", event.index + 1))
    bone = m.get("bone")
    if bone is not None and bone not in model.bone_names:
        hint = did_you_mean(str(bone), model.bone_names)
        raise SessionError(f"{where}: bone: expected a bone of the rig, got {shown(bone)}{hint}")
    if m["state"] == "up":
        if bone is None:
            pinned.clear()
        elif bone in pinned:
            pinned.discard(bone)
        else:
            raise SessionError(f"{where}: bone: expected a pinned bone, got {shown(bone)}")
        return Unpin(bone, line)
    if bone is None or bone in pinned:
        expected = "a bone to pin" if bone is None else "a bone that is not pinned yet"
        raise SessionError(f"{where}: bone: expected {expected}, got {shown(bone)}")
    limits = {key: _limit(where, m, key) for key in LIMITS}
    point = None if m.get("point") is None else frozen_vector(np.asarray(m["point"], float))
    pinned.add(bone)
    return Pin(bone, point, bool(m.get("orient", False)), line=line, **limits)


def _limit(where: str, message: dict, key: str) -> float:
    value = message.get(key, math.inf)
    ok = isinstance(value, int | float) and not isinstance(value, bool)
    if value is math.inf:
        return value
    if not (ok and math.isfinite(value) and value > 0):
        raise SessionError(f"{where}: {key}: expected a finite number > 0, got {shown(value)}")
    return float(value)
