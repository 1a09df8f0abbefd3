"""Session → what the runner runs: the estimated pointer track and the session's events.

Device side, once per 1 kHz tick (all ticks up front: the estimate does not depend on
the physics): counts − home counts → ``PoseEstimator.update`` → device pose → world pose
through the session's workspace.  A recording starts mid-stream, so before the first
tick the estimator (calibrated at home) is fed the first tick's counts until it settles
(at most ``WARMUP_TICKS``).  A session that stores ``/spidar/pose`` and no counts uses
those poses directly.

Multi-rate coupling, physics step h (any multiple of the tick or not):

- the pointer pose handed to the solver for the step [t, t + h] is the pose of the
  last tick at or before t + h; its velocity is the mean over the step,
  (pose(t + h) − pose(t))/h, exactly as for a scripted motion (``pointer_over_step``);
- a button or script event takes effect at the first step boundary at or after its tick;
- after each step the wrench on the hand (minus the coupling wrench, through the
  haptics low-pass and clamp) is rotated into the device frame and handed to the
  tension programme (``TensionDistributor``, warm-started) at the estimated pose of
  that step's tick; its tensions t and displayed wrench Aᵀt are held (zero-order hold)
  over the ticks of the next step, as the 2010 sample refreshed the grip force once
  per physics step.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from puppetcli.errors import ScriptError, SessionError, shown
from puppetcli.mcap.pin_events import pin_action
from puppetcli.mcap.session import Event, Session, read_session
from puppetcli.run.runner import Runner, TouchMode, UndoKey, Until
from puppetcli.run.trace import RunTrace
from puppetcli.script.actions import GRIP_DEFAULTS, Expect, Grip, Release, frozen_vector
from puppetcli.script.load import Key, Push, Script, script_from_text
from puppetcli.spidar import (
    DeviceError,
    PoseEstimator,
    TensionDistributor,
    TensionResult,
    check_reachable,
    lengths_from_counts,
)
from puppetcli.spidar.strings import MIN_LENGTH
from puppetcli.yamldoc import LARGEST, did_you_mean
from solver import quat, quat1
from solver.model import Model
from solver.spec import RigSpec
from solver.state import StepInput

__all__ = [
    "DeviceTrack",
    "EventActions",
    "Replay",
    "SessionRunner",
    "TrackLookup",
    "estimate_track",
    "load_replay",
    "replay_traced",
]

WARMUP_TICKS = 2000  # at most 2 s of the first sample before the recording starts
SOLVER_KEYS = ("h", "method", "iterations", "warm_start", "warm_start_factor")


class TrackLookup:
    """Pose look-up by time over per-tick arrays ``time``, ``world_pos``, ``world_quat``."""

    time: np.ndarray
    world_pos: np.ndarray
    world_quat: np.ndarray

    def index(self, t: float) -> int:
        """The last tick at or before t (the first tick for earlier times)."""
        k = int(np.searchsorted(self.time, t + 1e-9, side="right")) - 1
        return min(max(k, 0), len(self.time) - 1)

    def pose(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """World (position, quaternion) at time t, as ``pointer.Motion.pose``."""
        k = self.index(t)
        return self.world_pos[k], self.world_quat[k]

    def poses(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``pose`` at each of ``times``: (positions (n,3), quaternions (n,4))."""
        k = np.searchsorted(self.time, times + 1e-9, side="right") - 1
        k = np.clip(k, 0, len(self.time) - 1)
        return self.world_pos[k], self.world_quat[k]


@dataclass(frozen=True)
class DeviceTrack(TrackLookup):
    """The grip pose per tick: time (T,) s; device_pos (T,3) m, device_quat (T,4) in the
    device frame; world_pos (T,3) m, world_quat (T,4) through the workspace."""

    time: np.ndarray
    device_pos: np.ndarray
    device_quat: np.ndarray
    world_pos: np.ndarray
    world_quat: np.ndarray


def estimate_track(session: Session) -> DeviceTrack:
    """Estimated (or stored) grip poses of every tick, checked to be reachable."""
    if session.counts is not None:
        relative = session.counts - session.home_counts
        _check_lengths(session, relative)
        estimator = PoseEstimator(session.preset)
        _warm_up(estimator, relative[0])
        track = estimator.track(relative)
        t, pos, q, topic = session.tick_time, track.pos, track.quat, "/spidar/counts"
    else:
        t, pos, q = session.pose_time, session.pose_pos, session.pose_quat
        topic = "/spidar/pose"
    _check_reach(session, topic, t, pos, q)
    return DeviceTrack(t, pos, q, *session.workspace.world_from_device(pos, q))


def _warm_up(estimator: PoseEstimator, counts: np.ndarray) -> None:
    for _ in range(WARMUP_TICKS):
        before_pos, before_quat = estimator.pos, estimator.quat
        estimator.update(counts)
        moved = np.linalg.norm(estimator.pos - before_pos)
        turned = np.linalg.norm(quat.log(quat.mul(estimator.quat, quat.conj(before_quat))))
        if moved < 1e-12 and turned < 1e-10:
            return


def _check_lengths(session: Session, relative: np.ndarray) -> None:
    lengths = lengths_from_counts(session.preset, relative)
    bad = np.argwhere(lengths < MIN_LENGTH)
    if len(bad):
        i, s = (int(x) for x in bad[0])
        raise SessionError(
            f"{session.source}: /spidar/counts[{i}] (t = {session.tick_time[i]:.3f} s): "
            f"counts[{s}]: expected a string length of at least {MIN_LENGTH * 1e3:g} mm, "
            f"got {lengths[i, s] * 1e3:.4g} mm (count {session.counts[i, s]})"
        )


def _check_reach(session: Session, topic: str, t, pos: np.ndarray, q: np.ndarray) -> None:
    try:
        check_reachable(session.preset, pos, q, angle_max=None)
        return
    except DeviceError:
        pass
    for i in range(len(t)):
        try:
            check_reachable(session.preset, pos[i], q[i], angle_max=None)
        except DeviceError as exc:
            raise SessionError(
                f"{session.source}: {topic}[{i}] (t = {t[i]:.3f} s): expected a grip pose the "
                f"strings can reach, got {exc}"
            ) from None


# --- settings and events ------------------------------------------------------------------


def session_script(session: Session, track: DeviceTrack, spec: RigSpec) -> Script:
    """A Script carrying the session's run settings (its actions come from ``actions``), read
    by the script reader itself: the same keys, ranges and error words as a script's."""
    s = session.settings
    where = f"{session.source}: metadata.settings"
    pointer = s.get("pointer") or {} if isinstance(s, dict) else None
    if not isinstance(pointer, dict) or not isinstance(pointer.get("active", True), bool):
        expected = 'a JSON object whose "pointer" holds "radius" and "active" (true or false)'
        raise SessionError(f"{where}: expected {expected}, got {shown(s)}")
    doc: dict[str, Any] = {"actions": []}
    for key in ("h", "gravity", "solver", "haptics"):
        if s.get(key) is not None:
            doc[key] = s[key]
    if pointer.get("radius") is not None:
        doc["pointer"] = {"radius": pointer["radius"]}
    try:
        script = script_from_text(json.dumps(doc, allow_nan=False), where, spec)
    except ScriptError as exc:  # "FILE: metadata.settings:1: pointer.radius: expected …"
        raise SessionError(str(exc)) from None
    except (TypeError, ValueError, RecursionError) as exc:
        raise SessionError(
            f"{where}: expected the run settings of docs/sessions.md, got {shown(str(exc))}"
        ) from None
    duration = _setting_number(where, "duration", s.get("duration") or 0.0)
    duration = max(duration, session.end_time)
    return replace(
        script, duration=duration or None, pointer_start=frozen_vector(track.world_pos[0]),
        workspace_offset=frozen_vector(session.workspace.offset),
        workspace_scale=session.workspace.scale,
    )  # fmt: skip


def _setting_number(where: str, key: str, value: object) -> float:
    if not isinstance(value, int | float) or isinstance(value, bool) or not 0 <= value <= LARGEST:
        raise SessionError(
            f"{where}: {key}: expected a number in [0, {LARGEST:g}], got {shown(value)}"
        )
    return float(value)


def _name(event: Event, session: Session, key: str, known: list[str]) -> str:
    name = event.message.get(key)
    if name not in known:
        raise SessionError(
            f"{session.source}: {event.topic}[{event.index}]: {key}: expected a {key} of the rig, "
            f"got {shown(name)}{did_you_mean(str(name), known)}"
        )
    return name


def _vec(message: dict, key: str) -> np.ndarray | None:
    return None if message.get(key) is None else frozen_vector(message[key])


def _grip(event: Event, session: Session, model: Model) -> Grip:
    m = event.message
    bone = None if "bone" not in m else _name(event, session, "bone", model.bone_names)
    gains = {
        **GRIP_DEFAULTS,
        **{k: v for k, v in (m.get("gains") or {}).items() if k != "position_only"},
    }
    values = {k: float(gains[k]) for k in GRIP_DEFAULTS}
    position_only = bool((m.get("gains") or {}).get("position_only", False))
    point = _vec(m, "point") if bone is not None else None
    line = int(m.get("line", event.index + 1))
    return Grip(bone=bone, point=point, position_only=position_only, line=line, **values)


def _script_action(event: Event, session: Session, model: Model) -> Push | Expect:
    m, line = event.message, int(event.message.get("line", event.index + 1))
    if m["action"] == "push":
        return Push(
            _name(event, session, "bone", model.bone_names),
            _vec(m, "force") if "force" in m else frozen_vector(np.zeros(3)),
            _vec(m, "torque") if "torque" in m else frozen_vector(np.zeros(3)),
            _vec(m, "point") if "point" in m else frozen_vector(np.zeros(3)),
            float(m["duration"]), line,
        )  # fmt: skip
    joint = None if "joint" not in m else _name(event, session, "joint", model.joint_names)
    bone = None if "bone" not in m else _name(event, session, "bone", model.bone_names)
    return Expect(
        joint, bone, m.get("angle"), _vec(m, "rotation"), _vec(m, "head"), m.get("min_angle"),
        m.get("max_angle"), float(m.get("tolerance", 0.0)), line,
    )  # fmt: skip


class EventActions:
    """Turns a session's events, one after another, into the runner's actions.

    Buttons: grip down grips (ignored while gripping), grip up releases (ignored while
    free), key down takes a key (label or "key N"), touch down/up switches free-mode
    touching on/off, undo down drops the last key, pin down/up pins and unpins
    (puppetcli.mcap.pin_events); key up and other buttons are ignored.
    """

    def __init__(self, session: Session, model: Model) -> None:
        self.session, self.model = session, model
        self.gripping, self.keys = False, 0
        self.pinned: set[str] = set()

    def __call__(self, event: Event) -> object | None:
        """The action of ``event`` (None when it does nothing)."""
        m, session = event.message, self.session
        line = int(m.get("line", event.index + 1))
        if event.topic == "/script/events":
            return _script_action(event, session, self.model)
        button, down = m["button"], m["state"] == "down"
        if button == "grip" and down != self.gripping:
            self.gripping = down
            return _grip(event, session, self.model) if down else Release(int(m.get("line", 0)))
        if button == "key" and down:
            self.keys += 1
            return Key(m.get("label", f"key {self.keys}"), line)
        if button == "touch":
            return TouchMode(down, line)
        if button == "undo" and down:
            return UndoKey(line)
        if button == "pin":
            return pin_action(event, session, self.model, self.pinned)
        return None


def session_actions(session: Session, model: Model) -> tuple:
    """The runner's actions: each event's (``EventActions``) preceded by an ``Until`` its time."""
    actions: list = []
    to_action = EventActions(session, model)
    for event in session.events:
        action = to_action(event)
        if action is not None:
            actions += [Until(event.t), action]
    return tuple(actions)


# --- running ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class Replay:
    """A loaded session ready to run: its settings as a Script, the track, the actions."""

    session: Session
    script: Script
    track: DeviceTrack

    @property
    def warning(self) -> str | None:
        """What a user should know before the replay (an abruptly ended recording)."""
        if self.session.complete:
            return None
        return (
            f"{self.session.source}: the recording ended abruptly; replaying the "
            f"{self.session.end_time:.3f} s it holds"
        )

    @property
    def pointer_active(self) -> bool:
        return bool((self.session.settings.get("pointer") or {}).get("active", True))

    def runner(self, model: Model, trace=None, on_step=None, progress=None) -> SessionRunner:
        return SessionRunner(model, self, trace, on_step, progress)


def load_replay(path: Path, spec: RigSpec) -> Replay:
    """Read, check and estimate a session for the rig (``SessionError`` on any problem)."""
    session = read_session(path)
    track = estimate_track(session)
    return Replay(session, session_script(session, track, spec), track)


def replay_traced(replay: Replay, model: Model, trace_path: Path):
    """Run a loaded session on ``model`` (the rig's with the session's settings), tracing
    every step (and the device's channels) into ``trace_path``: the run's ``RunResult``."""
    runner = replay.runner(model)
    with RunTrace(trace_path, model, replay.script, 1, runner.pointer_on, spidar=True) as trace:
        runner.trace = trace
        return runner.run()


class SessionRunner(Runner):
    """A Runner whose pointer follows the device track and that runs the tension programme."""

    batch_steps = False  # the tension programme follows the displayed wrench step by step

    def __init__(
        self, model: Model, replay: Replay, trace=None, on_step=None, progress=None
    ) -> None:
        super().__init__(model, replay.script, trace, on_step, progress=progress)
        self.replay = replay
        self.motion = replay.track
        self.pointer_on = replay.pointer_active
        self.distributor = TensionDistributor(replay.session.preset)
        self.tensions: TensionResult | None = None
        self.actions = session_actions(replay.session, model)

    def run(self, actions: tuple | None = None):
        return super().run(self.actions if actions is None else actions)

    def _grip(self, action: Grip) -> None:
        try:
            super()._grip(action)
        except ScriptError as exc:
            detail = str(exc).split(": grip: ", 1)[-1]
            raise SessionError(
                f"{self.replay.session.source}: /spidar/buttons grip at t = "
                f"{self.sim.time:.3f} s: {detail}"
            ) from None

    def _after_step(self, inp: StepInput) -> None:
        super()._after_step(inp)
        if not self.pointer_on:
            return
        track, ws = self.replay.track, self.replay.session.workspace
        k = track.index(self.sim.time)
        to_device = quat1.conj(tuple(ws.orientation.tolist()))
        wanted = tuple(np.array(quat1.rotate(to_device, v)) for v in self.displayed)
        self.tensions = self.distributor.display(track.device_pos[k], track.device_quat[k], *wanted)
        if self.trace is not None:
            self.trace.spidar(self.sim.view(), track, k, self.tensions, wanted)
