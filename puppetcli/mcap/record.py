"""Script → session: the recording a SPIDAR-G device would have produced for a script.

The script runs once through the ``Runner`` (physics is needed: a ``twist`` turns about
the gripped bone's current axis, ``grip: {nearest: true}`` needs the current pose).  The
runner reports every action as it starts; the recorder keeps the pointer motions (the
same minimum-jerk ``Motion`` objects the runner used), the grips (resolved to a bone and
a bone-local point), releases, keys, pushes and expectations.  Then, per 1 kHz tick:

    pointer pose (world) = the motion in force at the tick, evaluated there
    device pose          = workspace⁻¹(world pose)
    counts               = counts_from_pose(preset, device pose) (+ seeded N(0, σ²) noise)

Workspace: the script's ``workspace:`` if it has one; otherwise fitted so the whole
pointer path fits in 80 % of the device's reach (``device_reach``): offset = centre of
the path's bounding box (rounded to 1 mm), scale = (largest distance of the path from
the offset) / (0.8 · reach), rounded up to two significant digits (the script default
4.0 when the pointer never moves).  Orientation: identity (device axes = world axes).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from puppetcli.errors import ScriptError
from puppetcli.mcap.pin_events import pin_button
from puppetcli.mcap.session import TICK, Event, Session, Workspace
from puppetcli.run.runner import Runner
from puppetcli.script.actions import Expect, Grip, Move, Release, Rotate, Touch, Twist
from puppetcli.script.load import DEFAULT_WORKSPACE_SCALE, Key, Push, Script
from puppetcli.script.pins import Pin, Unpin
from puppetcli.spidar import DeviceError, DevicePreset, check_reachable, counts_from_pose
from puppetcli.spidar.pointer import Motion, still
from solver import quat
from solver.model import Model

__all__ = ["FIT_FRACTION", "device_reach", "fit_workspace", "record_session"]

FIT_FRACTION = 0.8  # the fitted pointer path stays within this fraction of the reach
MOTIONS = (Move, Touch, Rotate, Twist)


def device_reach(dev: DevicePreset) -> float:
    """Radius (m) of the largest ball about home in which the grip centre can be, in any
    orientation, with every attachment point inside the frame: min plane distance − max |a_i|."""
    planes = dev.frame_planes
    return float(np.min(-planes[:, 3]) - np.max(np.linalg.norm(dev.grip_attach, axis=1)))


def fit_workspace(path_world: np.ndarray, dev: DevicePreset) -> Workspace:
    """The workspace that puts the pointer path (k,3) within 80 % of the device's reach."""
    lo, hi = path_world.min(axis=0), path_world.max(axis=0)
    offset = np.round(0.5 * (lo + hi), 3)
    radius = float(np.max(np.linalg.norm(path_world - offset, axis=1)))
    if radius < 1e-9:
        return Workspace(offset, DEFAULT_WORKSPACE_SCALE, fitted=True)
    scale = radius / (FIT_FRACTION * device_reach(dev))
    digits = 1 - math.floor(math.log10(scale))
    return Workspace(offset, math.ceil(scale * 10**digits) / 10**digits, fitted=True)


@dataclass
class _Tape:
    """What the runner did, in order: motions (start time, Motion, line) and events."""

    model: Model
    runner: Runner | None = None
    motions: list[tuple[float, Motion, int | None]] = field(default_factory=list)
    events: list[Event] = field(default_factory=list)

    def __call__(self, action: object, began: float) -> None:
        runner = self.runner
        if isinstance(action, MOTIONS):
            self.motions.append((began, runner.motion, action.line))
        elif isinstance(action, Grip):
            self._button(began, self._grip(action, runner), action.line)
        elif isinstance(action, Release):
            self._button(began, {"button": "grip", "state": "up"}, action.line)
        elif isinstance(action, Key):
            key = {"button": "key", "state": "down", "label": action.label}
            self._button(began, key, action.line)
            self._button(began, {"button": "key", "state": "up"}, action.line)
        elif isinstance(action, Pin | Unpin):
            self._button(began, _pin_fields(action), action.line)
        elif isinstance(action, Push):
            fields = {"bone": action.bone, "force": action.force, "torque": action.torque}
            fields |= {"point": action.point, "duration": action.duration}
            self._script(began, "push", fields, action.line)
        elif isinstance(action, Expect):
            self._script(began, "expect", _expect_fields(action), action.line)

    def _grip(self, action: Grip, runner: Runner) -> dict:
        c = runner.coupling
        m = self.model
        local = m.body_pos0[c.body] + c.anchor - m.bone_head0[c.body]
        gains = {k: getattr(action, k) for k in ("stiffness", "damping", "rot_stiffness")}
        gains |= {k: getattr(action, k) for k in ("rot_damping", "force_limit", "torque_limit")}
        gains |= {"reach": action.reach, "position_only": action.position_only}
        bone = m.bone_names[c.body]
        return {"button": "grip", "state": "down", "bone": bone, "point": local, "gains": gains}

    def _button(self, t: float, fields: dict, line: int) -> None:
        t = _tick_time(t)
        index = sum(e.topic == "/spidar/buttons" for e in self.events)
        message = {"t": t, **fields, "line": line}
        self.events.append(Event(t, "/spidar/buttons", index, message))

    def _script(self, t: float, action: str, fields: dict, line: int) -> None:
        t = _tick_time(t)
        index = sum(e.topic == "/script/events" for e in self.events)
        message = {"t": t, "action": action, **fields, "line": line}
        self.events.append(Event(t, "/script/events", index, message))


def _pin_fields(action: Pin | Unpin) -> dict:
    """A pin or unpin action as its ``/spidar/buttons`` fields (puppetcli.mcap.pin_events)."""
    if isinstance(action, Unpin):
        return pin_button(action.bone, False)
    limits = {"force_limit": action.force_limit, "torque_limit": action.torque_limit}
    return pin_button(action.bone, True, action.point, action.orient, limits)


def _tick_time(t: float) -> float:
    """The device tick at or after t (events take effect there)."""
    return math.ceil(t / TICK - 1e-6) * TICK


def _expect_fields(e: Expect) -> dict:
    names = ("joint", "bone", "angle", "rotation", "head", "min_angle", "max_angle", "tolerance")
    return {k: getattr(e, k) for k in names if getattr(e, k) is not None}


def _has_workspace(script: Script) -> bool:
    """Whether the script file gives ``workspace:`` (Script keeps only the values)."""
    try:
        doc = yaml.safe_load(Path(script.source).read_text(encoding="utf-8"))
    except (OSError, yaml.YAMLError):
        return False
    return isinstance(doc, dict) and doc.get("workspace") is not None


def _settings(script: Script, pointer_on: bool) -> dict:
    return {
        "h": script.h,
        "duration": script.duration,
        "gravity": script.gravity,
        "solver": dict(script.solver),
        "pointer": {"radius": script.pointer_radius, "active": pointer_on},
        "haptics": {"max_force": script.max_force, "max_torque": script.max_torque,
                    "lowpass": script.lowpass},
    }  # fmt: skip


def _sample(tape: _Tape, start: Motion, times: np.ndarray) -> tuple[np.ndarray, np.ndarray, list]:
    """World pointer poses at ``times`` and the script line in force at each."""
    pos, rot = np.empty((len(times), 3)), np.empty((len(times), 4))
    lines: list[int | None] = []
    k, motion, line = 0, start, None
    for i, t in enumerate(times):
        while k < len(tape.motions) and tape.motions[k][0] <= t + 1e-9:
            _, motion, line = tape.motions[k]
            k += 1
        pos[i], rot[i] = motion.pose(float(t))
        lines.append(line)
    return pos, rot, lines


def record_session(
    model: Model,
    script: Script,
    dev: DevicePreset,
    noise: float = 0.0,
    seed: int = 0,
    store_pose: bool = False,
) -> Session:
    """Run ``script`` on ``model`` (the rig's, with the script's settings:
    ``script_model``) and return the session a device ``dev`` would record.

    noise: σ of Gaussian noise added to every count (counts, seeded by ``seed``).
    Raises ``ScriptError`` naming the script line when the pointer path leaves the device.
    """
    tape = _Tape(model)
    runner = tape.runner = Runner(model, script, on_action=tape)
    start = still(np.asarray(script.pointer_start, dtype=float), quat.IDENTITY)
    result = runner.run()
    if result.error is not None:
        raise result.error
    times = np.arange(round(result.state.time / TICK) + 1) * TICK
    world_pos, world_quat, lines = _sample(tape, start, times)
    fitted = not _has_workspace(script)
    workspace = (
        fit_workspace(world_pos, dev)
        if fitted
        else Workspace(np.array(script.workspace_offset), script.workspace_scale)
    )
    dev_pos, dev_quat = workspace.device_from_world(world_pos, world_quat)
    _check_path(script, dev, dev_pos, dev_quat, times, lines)
    counts = counts_from_pose(dev, dev_pos, dev_quat, check=False)
    if noise > 0.0:
        rng = np.random.default_rng(seed)
        counts = counts + np.rint(rng.normal(0.0, noise, counts.shape)).astype(np.int64)
    recorder = {"script": script.source, "rig": model.name, "noise": noise, "seed": seed}
    return Session(
        preset=dev,
        workspace=workspace,
        home_counts=np.zeros(dev.n_strings, dtype=np.int64),
        settings=_settings(script, runner.pointer_on),
        recorder=recorder,
        tick_time=times,
        counts=counts,
        pose_time=times if store_pose else None,
        pose_pos=dev_pos if store_pose else None,
        pose_quat=dev_quat if store_pose else None,
        events=tuple(tape.events),
        source=script.source,
    )


def _check_path(
    script: Script, dev: DevicePreset, pos: np.ndarray, q: np.ndarray, times, lines
) -> None:
    """ScriptError naming the script line of the first tick the strings cannot reach."""
    try:
        check_reachable(dev, pos, q)
        return
    except DeviceError:
        pass
    for i in range(len(times)):
        try:
            check_reachable(dev, pos[i], q[i])
        except DeviceError as exc:
            where = f"{script.source}:{lines[i]}" if lines[i] is not None else script.source
            raise ScriptError(
                f"{where}: at t = {times[i]:.3f} s: expected a pointer pose the device's strings "
                f"can reach, got {exc}"
            ) from None
