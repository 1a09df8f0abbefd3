"""A live session: the doll stepped on the page's input, recorded as a device session.

The recording *is* a session being written: every input becomes the event a device
would record, and the simulation runs those events through the replay's own machinery
(``SessionRunner`` over a growing ``LiveTrack``, ``EventActions`` turning each recorded
event into the runner's action).  So ``puppetcli pose RIG SESSION.mcap`` replays exactly
what was run live: the same ticks, the same events at the same step boundaries.

One physics step [t, t + h] (``step``):

1. at the boundary t, the queued commands become events stamped t (``/spidar/buttons``)
   and act (a replay acts on an event at the first boundary at or after its time);
2. device ticks up to t + h: the pointer filter moves towards the page's target, each
   tick is written as ``/spidar/pose`` (device frame) and appended to the track;
3. the runner steps; its trace hooks write what the hand felt (``/haptic/wrench``:
   requested and displayed wrench) and the device's tension programme
   (``/spidar/tensions``), exactly the channels a replay's trace has.

A click on a bone takes two boundaries: at t the pointer jumps to the clicked point
(touching switched off around the jump, so the pointer does not strike the bone it
lands in), at t + h the grip-down event grips that bone at that point.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from puppetcli.live.track import LiveTrack, PointerFilter, device_from_world
from puppetcli.mcap.pin_events import pin_button
from puppetcli.mcap.replay import EventActions, Replay, SessionRunner, session_script
from puppetcli.mcap.session import TICK, Event, Session, SessionWriter, Workspace
from puppetcli.run.build import compile_engine
from puppetcli.run.runner import script_model
from puppetcli.run.trace import tensions_message, wrench_message
from puppetcli.script.actions import GRIP_DEFAULTS
from puppetcli.script.load import DEFAULT_LOWPASS, DEFAULT_MAX_FORCE, DEFAULT_MAX_TORQUE
from puppetcli.spidar import DevicePreset, TensionDistributor
from solver import quat
from solver.model import Model, build_model
from solver.rows.grip import nearest_point
from solver.spec import RigSpec
from solver.state import StepInput, StepReport

__all__ = [
    "Grip", "Key", "LiveRecording", "Pin", "Release", "Touch", "Undo", "Unpin", "live_settings",
]  # fmt: skip

HAPTIC_CHANNELS = {
    "/haptic/wrench": "puppetcli.HapticWrench",
    "/spidar/tensions": "puppetcli.SpidarTensions",
}
POINTER_RADIUS = 0.02  # m: the free pointer's contact sphere


@dataclass(frozen=True)
class Grip:
    """Grip ``bone`` at the world ``point`` (the pointer jumps there), or with ``bone`` None
    the bone nearest the pointer within reach; ``position_only`` None: the session's
    setting."""

    bone: str | None = None
    point: np.ndarray | None = None
    position_only: bool | None = None


@dataclass(frozen=True)
class Release:
    """Let go."""


@dataclass(frozen=True)
class Touch:
    """Free-mode touching on or off."""

    on: bool


@dataclass(frozen=True)
class Key:
    """Take a key (``label`` None: "key N")."""

    label: str | None = None


@dataclass(frozen=True)
class Undo:
    """Drop the last key."""


@dataclass(frozen=True)
class Pin:
    """Pin ``bone`` at the world ``point`` (m), its orientation too when ``orient``."""

    bone: str
    point: np.ndarray
    orient: bool = False


@dataclass(frozen=True)
class Unpin:
    """Unpin ``bone`` (None: every bone)."""

    bone: str | None = None


def live_settings(h: float | None) -> dict:
    """A live session's run settings (the session metadata's ``settings``)."""
    return {
        "h": h, "duration": None, "gravity": True, "solver": {},
        "pointer": {"radius": POINTER_RADIUS, "active": True},
        "haptics": {"max_force": DEFAULT_MAX_FORCE, "max_torque": DEFAULT_MAX_TORQUE,
                    "lowpass": DEFAULT_LOWPASS},
    }  # fmt: skip


class LiveRecording:
    """The live simulation and the session file it writes as it goes (module docstring).

    f: the open binary file of the session; start_pos, start_quat: the pointer's world pose
    at t = 0.  ``step`` advances one physics step; the commands (``Grip`` …) queued with
    ``submit`` act at the next step boundary; ``target`` is the pointer pose the page wants.
    """

    def __init__(
        self, spec: RigSpec, f, dev: DevicePreset, workspace: Workspace, h: float | None,
        start_pos: np.ndarray, start_quat: np.ndarray, recorder: dict,
    ) -> None:  # fmt: skip
        self.track = LiveTrack(workspace)
        session = Session(
            preset=dev, workspace=workspace, home_counts=np.zeros(dev.n_strings, np.int64),
            settings=live_settings(h), recorder=recorder, source=str(getattr(f, "name", "")),
        )  # fmt: skip
        self.writer = SessionWriter(f, session, ["/spidar/pose"], HAPTIC_CHANNELS)
        self.set_target(start_pos, start_quat)
        self.filter = PointerFilter(*self.target)
        self.jumping = False
        self._tick(0)
        script = session_script(session, self.track, spec)
        self.model: Model = script_model(build_model(spec), script)
        self.tap = _Tap(self.writer)
        self.runner = SessionRunner(self.model, Replay(session, script, self.track), trace=self.tap)
        self.to_action = EventActions(session, self.model)
        self.queue: deque = deque()
        self.position_only, self.touch = True, False
        self._pending_grip: dict | None = None
        self._button(0.0, {"button": "touch", "state": "up"})  # live touching starts off

    # --- input -------------------------------------------------------------------------

    def submit(self, command: object) -> None:
        """Queue a command for the next step boundary."""
        self.queue.append(command)

    def set_target(self, pos, q) -> None:
        """The pointer pose the page asks for (already clamped to the workspace)."""
        self.target = (tuple(map(float, pos)), tuple(map(float, q)))

    # --- one step ----------------------------------------------------------------------

    @property
    def time(self) -> float:
        return self.runner.state.time

    def step(self) -> None:
        """Act on the queued commands at this boundary, make the ticks, step once."""
        self._boundary()
        h = self.model.options.h
        k = len(self.track)
        while k * TICK <= self.time + h + 1e-9:
            self._tick(k)
            k += 1
        self.runner.advance(h)

    def _tick(self, k: int) -> None:
        if self.jumping:
            self.filter.jump(*self.target)
            self.jumping = False
        elif k > 0:
            self.filter.tick(*self.target)
        pos, q = device_from_world(self.track.workspace, self.filter.pos, self.filter.quat)
        t = k * TICK
        self.writer.add("/spidar/pose", t, {"t": t, "position": pos, "orientation": q})
        self.track.append(t, pos, q)

    def act(self) -> None:
        """Act on the queued commands now, without stepping (while the physics is paused):
        keys, undo, touch, release; a grip waits for the physics (its jump needs ticks)."""
        while self.queue and self._pending_grip is None:
            if isinstance(self.queue[0], Grip):
                return
            self._command(self.queue.popleft())

    def _boundary(self) -> None:
        if self._pending_grip is not None:
            self._button(self.time, self._pending_grip)
            self._pending_grip = None
            if self.touch:
                self._button(self.time, {"button": "touch", "state": "down"})
            return
        while self.queue:
            command = self.queue.popleft()
            if self._command(command):
                return  # a grip's jump: the rest waits for the next boundary

    def _command(self, c: object) -> bool:
        """Act on one command; True when it occupies the boundary (a grip's jump)."""
        t, gripping = self.time, self.runner.coupling is not None
        if isinstance(c, Grip) and not gripping:
            return self._grip(c)
        if isinstance(c, Release) and gripping:
            self._button(t, {"button": "grip", "state": "up"})
        elif isinstance(c, Touch) and c.on != self.touch:
            self.touch = c.on
            self._button(t, {"button": "touch", "state": "down" if c.on else "up"})
        elif isinstance(c, Key):
            label = c.label or f"key {self.to_action.keys + 1}"  # as a replay names it
            self._button(t, {"button": "key", "state": "down", "label": label})
            self._button(t, {"button": "key", "state": "up"})
        elif isinstance(c, Undo) and len(self.runner.keys):
            self._button(t, {"button": "undo", "state": "down"})
        elif isinstance(c, Pin | Unpin):
            self._pin(c)
        return False

    def _pin(self, c: Pin | Unpin) -> None:
        """A pin or unpin event (nothing for a bone pinned already, or not pinned)."""
        pinned = self.runner.board.names
        if isinstance(c, Unpin):
            if pinned and (c.bone is None or c.bone in pinned):
                self._button(self.time, pin_button(c.bone, False))
            return
        if c.bone in pinned:
            return
        local = self._rest_offset(self.model.bone_names.index(c.bone), np.asarray(c.point, float))
        self._button(self.time, pin_button(c.bone, True, local, c.orient))

    def _rest_offset(self, b: int, point: np.ndarray) -> np.ndarray:
        """The world ``point`` carried by bone b, as an offset from its head in its rest
        pose (how sessions store grip and pin points)."""
        state = self.runner.state
        anchor = quat.rotate(quat.conj(state.body_quat[b]), point - state.body_pos[b])
        return self.model.body_pos0[b] + anchor - self.model.bone_head0[b]

    def _grip(self, c: Grip) -> bool:
        m, state = self.model, self.runner.state
        if c.bone is None:
            b, point, dist = nearest_point(m, state, np.array(self.filter.pos))
            if dist > GRIP_DEFAULTS["reach"]:
                raise NothingInReach(m.bone_names[b], dist)
        else:
            b, point = m.bone_names.index(c.bone), np.asarray(c.point, float)
        local = self._rest_offset(b, point)
        only = self.position_only if c.position_only is None else c.position_only
        gains = GRIP_DEFAULTS | {"position_only": only}
        message = {"button": "grip", "state": "down", "bone": m.bone_names[b], "point": local,
                   "gains": gains}  # fmt: skip
        if c.bone is None:
            self._button(self.time, message)
            return False
        self.set_target(point, self.target[1])
        self.jumping = True
        if self.touch:
            self._button(self.time, {"button": "touch", "state": "up"})
        self._pending_grip = message
        return True

    def _button(self, t: float, fields: dict) -> None:
        """Record a button event at t and act on it as a replay will."""
        index = self.writer.count("/spidar/buttons")
        message = {"t": t, **fields}
        self.writer.add("/spidar/buttons", t, message)
        action = self.to_action(Event(t, "/spidar/buttons", index, message))
        if action is not None:
            self.runner.act(action)

    def warm_up(self) -> None:
        """Run the compiled parts once on throwaway inputs (the step, the tension programme):
        numba compiles or loads them now rather than in the first live step."""
        compile_engine(self.model)
        TensionDistributor(self.runner.distributor.preset).display(
            np.zeros(3), quat.IDENTITY, np.zeros(3), np.zeros(3)
        )

    def flush(self) -> None:
        """Push everything recorded so far to the disk (a kill after this loses nothing)."""
        self.writer.flush()

    def close(self) -> None:
        """Complete the session file (summary and footer)."""
        self.writer.finish()

    @property
    def gripping(self) -> str | None:
        """The gripped bone's name, or None."""
        c = self.runner.coupling
        return None if c is None else self.model.bone_names[c.body]


class _Tap:
    """The runner's trace: writes what the hand felt and the tension programme's output
    each step (the channels of a replay's trace) and keeps the latest for the page."""

    def __init__(self, writer: SessionWriter) -> None:
        self.writer = writer
        self.report: StepReport | None = None
        self.requested = self.displayed = (np.zeros(3), np.zeros(3))
        self.tensions = None

    def step(self, s, report: StepReport, inp: StepInput, coupling, requested, displayed):
        self.report, self.requested, self.displayed = report, requested, displayed
        self.writer.add("/haptic/wrench", s.time, wrench_message(s.time, requested, displayed))

    def spidar(self, s, track, k: int, shown, wanted: tuple) -> None:
        self.tensions = shown
        self.writer.add("/spidar/tensions", s.time, tensions_message(s.time, shown, wanted))

    def keyframe(self, t: float, label: str, line: int, index: int, undo: bool = False) -> None:
        """A key (or its undo) is recorded by its button event."""


class NothingInReach(Exception):
    """A grip of the nearest bone found none within reach."""

    def __init__(self, bone: str, dist: float) -> None:
        super().__init__(
            f"grip: no bone within {GRIP_DEFAULTS['reach']:g} m of the pointer "
            f"(nearest: {bone} at {dist:.2f} m)"
        )
