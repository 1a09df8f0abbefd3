"""Run a manipulation script: the timeline, the pointer, grips, keys, expectations, trace.

Actions run one after another on one timeline. A timed action (push, wait, move, touch,
rotate, twist) ends at its start time plus its duration; the simulation steps while t <
t_end − h/2, so durations that are not multiples of h do not accumulate rounding. Steps
run in place on the model's engine (solver.Engine's stepper: the compiled step,
identical to solver.pipeline.step to rounding, which it falls back to for anything it
does not handle); a timed action's pointer poses are computed for all of its steps at
once, so a step costs little Python beside the solver. The pointer keeps its last pose
between motions, and a grip holds through waits and pushes until `release`. A key
captures the state when it is reached. If the simulation fails, the keys and expectation
results so far are returned with the error, and the trace keeps every step written.

A session replay (puppetcli.mcap.replay) drives the same runner: its pointer follows the
device's estimated pose (any object with ``pose(t)``, like ``Motion``) and its
actions are the session's events, each preceded by an ``Until`` that steps to the
first step boundary at or after the event's time.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from puppetcli.errors import Interrupted, RunStopped, ScriptError
from puppetcli.run.interrupt import StepBoundary
from puppetcli.run.keyframes import KeyframeSet
from puppetcli.run.pins import PinBoard
from puppetcli.run.snapshot import capture, push_input
from puppetcli.run.trace import RunTrace
from puppetcli.script.actions import Expect, Grip, Move, Release, Rotate, Touch, Twist
from puppetcli.script.expect import ExpectResult, check
from puppetcli.script.load import Key, Push, Script, Wait
from puppetcli.script.pins import Pin, Unpin
from puppetcli.spidar.haptics import HapticChain, norm3, row_norms
from puppetcli.spidar.pointer import Motion, pointer_path, still
from solver import quat
from solver.engine import Engine
from solver.errors import SimulationError
from solver.model import Model
from solver.observe import bone_points
from solver.rows.grip import (
    Coupling,
    Pointer,
    any_within,
    bone_reach,
    make_coupling,
    nearest_point,
    path_input,
)
from solver.state import State, StepInput, initial_state

POINTER_ACTIONS = (Grip, Move, Rotate, Twist, Release, Touch)
BATCH = 1024  # steps of a batch between progress calls (the run budget's watch reads them)
EVENT_SLACK = 1e-9  # s: an event "at" a step boundary despite float rounding of the time


@dataclass(frozen=True)
class Until:
    """Step to the first step boundary at or after ``time`` (s): a replay's wait for an event."""

    time: float
    line: int = 0


@dataclass(frozen=True)
class TouchMode:
    """A session's touch switch: the free pointer pushes what it meets (on) or nothing (off).
    Switched on inside a bone, it touches nothing until clear of the bones (as after a
    release)."""

    on: bool
    line: int = 0


@dataclass(frozen=True)
class UndoKey:
    """A session's undo button: drop the last key taken."""

    line: int = 0


@dataclass
class RunResult:
    """What a run produced."""

    keys: KeyframeSet
    state: State
    steps: int
    wall_time: float
    expectations: list[ExpectResult] = field(default_factory=list)
    peak_force: float = 0.0
    peak_displayed: float = 0.0
    error: SimulationError | RunStopped | None = None


def script_model(model: Model, script: Script) -> Model:
    """The model with the script's settings (step, gravity, solver overrides) applied."""
    changes = dict(script.solver)
    if script.h is not None:
        changes["h"] = script.h
    if not script.gravity:
        changes["gravity"] = np.zeros(3)
    return model.with_options(**changes)


class Runner:
    """Steps a model through a script."""

    batch_steps = True  # a timed action's steps may run in batches (``_batched``)

    def __init__(
        self,
        model: Model,
        script: Script,
        trace: RunTrace | None = None,
        on_step: Callable[[State], None] | None = None,
        on_action: Callable[[object, float], None] | None = None,
        progress: Callable[[int], None] | None = None,
    ) -> None:
        self.model, self.script, self.trace, self.on_step = model, script, trace, on_step
        self.on_action = on_action  # called after each action with the time it started
        self.progress = progress  # called with the number of steps just taken
        self.sim = Engine(model).stepper(initial_state(model))
        self.keys = KeyframeSet()
        self.motion: Motion = still(np.asarray(script.pointer_start, dtype=float), quat.IDENTITY)
        self.pointer_on = any(isinstance(a, POINTER_ACTIONS) for a in script.actions)
        self.coupling: Coupling | None = None
        self.board = PinBoard(model)  # pins hold through every other action until unpinned
        self.touch_enabled = True  # free-mode touching (a session's touch switch)
        self.touch_suspended = False  # after a release, until the pointer is clear of the bones
        self.reach = bone_reach(model)
        self.haptics = HapticChain(script.max_force, script.max_torque, script.lowpass)
        self.expectations: list[ExpectResult] = []
        self.peak = self.peak_since_key = self.peak_displayed = 0.0
        self.displayed = ((0.0,) * 3, (0.0,) * 3)  # the last step's wrench on the hand
        self._handlers: dict | None = None
        self.upgrade: Callable[[], bool] | None = None  # True: move to the compiled step
        self.boundary = StepBoundary()  # Ctrl-C is taken before a step, never within one

    @property
    def state(self) -> State:
        """The current state (a copy: read it between actions, not every step)."""
        return self.sim.state

    def run(self, actions: tuple | None = None) -> RunResult:
        """Run every action (the script's unless given), then wait out the script's duration."""
        start = time.perf_counter()
        error = None
        with self.boundary:
            try:
                for action in self.script.actions if actions is None else actions:
                    self.act(action)
                if self.script.duration is not None:
                    self.advance(self.script.duration - self.sim.time)
            except (SimulationError, RunStopped) as exc:
                error = exc
            except KeyboardInterrupt:  # Ctrl-C: the run ends here; its keys and trace are kept
                error = Interrupted(self.sim.steps, self.sim.time)
            if self.trace is not None:
                self.trace.flush()  # the trace's last steps are part of the run's time
            if self.boundary.requested and error is None:  # Ctrl-C as the run ended
                error = Interrupted(self.sim.steps, self.sim.time)
        return RunResult(
            self.keys, self.sim.state, self.sim.steps, time.perf_counter() - start,
            self.expectations, self.peak, self.peak_displayed, error,
        )  # fmt: skip

    def act(self, action: object) -> None:
        """Carry out one action (steps the simulation for a timed one)."""
        if self._handlers is None:
            self._handlers = self._handler_table()
        self.boundary.check()
        if self.upgrade is not None and self.upgrade():
            self._upgrade()
        began = self.sim.time
        self._handlers[type(action)](action)
        if self.on_action is not None:
            self.on_action(action, began)

    def _upgrade(self) -> None:
        """Go on from the current state on the compiled step (puppetcli.run.warmup: the numpy
        step ran until the compiled one was built)."""
        self.upgrade = None
        self.model = self.model.with_options(engine="compiled")
        self.sim = Engine(self.model).stepper(self.sim.state)

    def _handler_table(self) -> dict:
        return {
            Push: lambda a: self.advance(a.duration, a),
            Wait: lambda a: self.advance(a.duration),
            Key: self._key,
            Expect: lambda a: self.expectations.append(
                check(self.model, self.state, a, self.script.source)
            ),
            Grip: self._grip,
            Release: self._release,
            Move: self._move,
            Touch: self._move,
            Rotate: lambda a: self._turn(a.axis * a.angle, a.duration),
            Twist: self._twist,
            Until: lambda a: self.advance(
                a.time - self.sim.time + 0.5 * self.model.options.h - EVENT_SLACK
            ),
            TouchMode: self._touch_mode,
            UndoKey: self._undo,
            Pin: self._pin,
            Unpin: lambda a: self.board.unpin(a.bone),
        }

    def _pin(self, action: Pin) -> None:
        self.board.pin_rest_point(
            self.state, action.bone, action.point, orient=action.orient,
            force_limit=action.force_limit, torque_limit=action.torque_limit,
        )  # fmt: skip

    def _undo(self, action: UndoKey) -> None:
        if not len(self.keys):
            return
        key = self.keys.pop()
        if self.trace is not None:
            self.trace.keyframe(self.sim.time, key.label, action.line, len(self.keys) + 1, True)

    def _touch_mode(self, action: TouchMode) -> None:
        self.touch_enabled = action.on
        self.touch_suspended = action.on

    def _key(self, action: Key) -> None:
        extra = {"line": action.line, "peak_force": self.peak_since_key}
        self.keys.add(capture(self.model, self.state, action.label, extra))
        self.peak_since_key = 0.0
        if self.trace is not None:
            self.trace.keyframe(self.sim.time, action.label, action.line, len(self.keys))

    def _pointer_pose(self) -> tuple[np.ndarray, np.ndarray]:
        return self.motion.pose(self.sim.time)

    def _move(self, action: Move | Touch) -> None:
        pos, q = self._pointer_pose()
        delta = action.by if action.by is not None else action.to - pos
        self.motion = Motion(self.sim.time, action.duration, pos, q, np.asarray(delta), np.zeros(3))
        self.advance(action.duration)

    def _turn(self, rotvec: np.ndarray, duration: float) -> None:
        pos, q = self._pointer_pose()
        self.motion = Motion(self.sim.time, duration, pos, q, np.zeros(3), np.asarray(rotvec))
        self.advance(duration)

    def _twist(self, action: Twist) -> None:
        b = self.coupling.body
        ends = np.stack((self.model.bone_head0[b], self.model.bone_tail0[b]))
        head, tail = bone_points(self.model, self.state, ends, bones=np.array([b, b]))
        axis = (tail - head) / max(np.linalg.norm(tail - head), 1e-12)
        self._turn(axis * action.angle, action.duration)

    def _grip(self, action: Grip) -> None:
        pos, _ = self._pointer_pose()
        if action.bone is None:
            b, point, dist = nearest_point(self.model, self.state, pos)
            if dist > action.reach:
                raise ScriptError(
                    f"{self.script.source}:{action.line}: grip: expected a bone within "
                    f"{action.reach:g} m of the pointer, "
                    f"got '{self.model.bone_names[b]}' at {dist:.3f} m"
                )
        else:
            b = self.model.bone_names.index(action.bone)
            point = self._grip_point(b, action.point, pos)
        # The pointer as it is now (a replay's track keeps moving; a script's motion is done).
        now = Pointer(*self._pointer_pose(), np.zeros(3), np.zeros(3))
        self.coupling = make_coupling(
            self.state, now, b, point,
            stiffness=action.stiffness, damping=action.damping, rot_stiffness=action.rot_stiffness,
            rot_damping=action.rot_damping, force_limit=action.force_limit,
            torque_limit=action.torque_limit, position_only=action.position_only,
        )  # fmt: skip

    def _grip_point(self, b: int, local: np.ndarray | None, pointer_pos: np.ndarray) -> np.ndarray:
        """World grip point: the bone-local point given, else the bone's point nearest the
        pointer."""
        if local is None:
            bone = np.full(len(self.model.bone_names), False)
            bone[b] = True
            return nearest_point(self.model, self.state, pointer_pos, bone)[1]
        rest = self.model.bone_head0[b] + local
        return bone_points(self.model, self.state, rest[None], bones=np.array([b]))[0]

    def _release(self, action: Release) -> None:
        # The hand that let go is still inside the bone: it touches nothing until clear.
        self.coupling = None
        self.touch_suspended = True

    def _touching(self, pos: np.ndarray) -> bool:
        """Free-mode touching is on, unless switched off, or suspended after a release (or
        switching on) and not yet clear."""
        if not self.touch_enabled:
            return False
        if self.touch_suspended:
            gap = self.reach + self.script.pointer_radius + self.model.options.contact_margin
            self.touch_suspended = any_within(self.model, self.sim.view(), pos, gap)
        return not self.touch_suspended

    def advance(self, duration: float, push: Push | None = None) -> None:
        """Step until ``duration`` seconds have passed (nothing to do when ≤ 0)."""
        sim, h = self.sim, self.model.options.h
        t_end, starts, t = sim.time + duration, [], sim.time
        while t < t_end - 0.5 * h:  # the times the stepper will reach, by the same sums
            starts.append(t)
            t += h
        if not starts:
            return
        poses = pointer_path(self.motion, np.array(starts + [t]), h) if self.pointer_on else None
        for k in range(len(starts)):
            if self._batched(push):  # from here on, every input is known
                for first in range(k, len(starts), BATCH):  # progress between batches
                    self.boundary.check()
                    self._run_batch(poses, first, min(first + BATCH, len(starts)))
                return
            self.boundary.check()
            inp = self._input(push, poses, k)
            sim.advance(inp)
            self._after_step(inp)

    def _batched(self, push: Push | None) -> bool:
        """True when every input of the steps is known before they run and nothing needs
        them one by one (no trace, no per-step callback, no push, no free pointer still
        waiting to be clear of the bones)."""
        waiting = self.coupling is None and self.touch_enabled and self.touch_suspended
        return (
            self.batch_steps and push is None and self.trace is None and self.on_step is None
            and not (self.pointer_on and waiting) and not self.board
        )  # fmt: skip

    def _input(self, push: Push | None, poses, k: int) -> StepInput:
        inp = self._pointer_input(push, poses, k)
        return replace(inp, pins=self.board.pins) if self.board else inp

    def _pointer_input(self, push: Push | None, poses, k: int) -> StepInput:
        loads = push_input(self.model, self.sim.view(), push) if push is not None else None
        if poses is None:
            return loads or StepInput()
        pos, path = poses
        free = self.coupling is None and self._touching(pos[k])
        radius = self.script.pointer_radius if free else 0.0
        inp = path_input(path, k, radius, self.coupling)
        if loads is None:
            return inp
        return replace(inp, body_force=loads.body_force, body_torque=loads.body_torque)

    def _run_batch(self, poses, first: int, end: int) -> None:
        """Steps first … end − 1 of ``poses``, whose inputs are all known: stepped with
        nothing else in the loop, their wrenches felt afterwards (the same floats as
        step by step)."""
        n = end - first
        wrench = np.empty((n, 9))  # grip force, grip torque, touch force
        if poses is None:
            for row in wrench:
                self.sim.advance()
                self.sim.wrench_into(row)
        else:
            free = self.coupling is None and self.touch_enabled
            radius = self.script.pointer_radius if free else 0.0
            path = tuple(a[first:end] for a in poses[1])
            self.sim.follow(path, radius, self.coupling, wrench)
        self._feel(wrench)
        if self.progress is not None:
            self.progress(n)

    def _feel(self, wrench: np.ndarray) -> None:
        """Peaks and the haptic chain over the rows of ``wrench`` (n, 9), as
        ``_after_step`` does row by row."""
        on_doll = wrench[:, 0:3] if self.coupling is not None else wrench[:, 6:9]
        requested = -np.concatenate((on_doll, wrench[:, 3:6]), axis=1)  # on the hand
        force = float(row_norms(on_doll).max())
        self.peak = max(self.peak, force)
        self.peak_since_key = max(self.peak_since_key, force)
        shown = self.haptics.display_many(requested)
        self.displayed = (tuple(shown[-1, :3].tolist()), tuple(shown[-1, 3:].tolist()))
        self.peak_displayed = max(self.peak_displayed, float(row_norms(shown[:, :3]).max()))

    def _after_step(self, inp: StepInput) -> None:
        if self.board:
            self.board.after_step(self.sim.view(), self.sim.report)
        grip_force, grip_torque, touch_force = self.sim.wrench()
        fx, fy, fz = (grip_force if self.coupling is not None else touch_force).tolist()
        tx, ty, tz = grip_torque.tolist()
        requested = ((-fx, -fy, -fz), (-tx, -ty, -tz))  # on the hand
        force = norm3((fx, fy, fz))
        self.peak = max(self.peak, force)
        self.peak_since_key = max(self.peak_since_key, force)
        self.displayed = shown = self.haptics.display(*requested)
        self.peak_displayed = max(self.peak_displayed, norm3(shown[0]))
        if self.progress is not None:
            self.progress(1)
        if self.on_step is not None:
            self.on_step(self.sim.state)
        if self.trace is not None:
            self.trace.step(
                self.sim.view(), self.sim.report, inp, self.coupling, requested, shown,
            )  # fmt: skip
