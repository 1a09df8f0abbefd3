"""Run a manipulation script on a model: the timeline, key capture and the trace.

Actions run one after another on one timeline.  A timed action (push, wait)
ends at its start time plus its duration; the simulation steps while
t < t_end − h/2, so durations that are not multiples of h do not accumulate
rounding.  A key captures the state at the moment it is reached.  If the
simulation fails, the keys taken so far are returned with the error, and the
trace keeps every step written before it.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from puppetcli.keyframes import BonePose, Keyframe, KeyframeSet
from puppetcli.script import Key, Push, Script, Wait
from puppetcli.trace import TraceWriter
from solver import quat
from solver.errors import SimulationError
from solver.model import Model
from solver.observe import bone_heads, bone_tails, joint_rotations, relative_rotations
from solver.state import State, StepInput, StepReport, initial_state
from solver.step import step


@dataclass
class RunResult:
    """What a run produced: keys, final state, step count, wall time, and the error if it failed."""

    keys: KeyframeSet
    state: State
    steps: int
    wall_time: float
    error: SimulationError | None = None


def script_model(model: Model, script: Script) -> Model:
    """The model with the script's settings (step, gravity, solver overrides) applied."""
    changes = dict(script.solver)
    if script.h is not None:
        changes["h"] = script.h
    if not script.gravity:
        changes["gravity"] = np.zeros(3)
    return model.with_options(**changes)


def push_input(model: Model, state: State, push: Push) -> StepInput:
    """Force and torque about the bone's centre of mass for a push at a bone-local point."""
    b = model.bone_names.index(push.bone)
    local = model.bone_head0[b] - model.body_pos0[b] + push.point
    arm = quat.rotate(state.body_quat[b], local)
    force = np.zeros((model.nbody, 3))
    torque = np.zeros((model.nbody, 3))
    force[b] = push.force
    torque[b] = push.torque + np.cross(arm, push.force)
    return StepInput(body_force=force, body_torque=torque)


def capture(model: Model, state: State, label: str, extra: dict) -> Keyframe:
    """A keyframe of every bone: head position, rotation from rest, joint rotation from rest."""
    nbone = len(model.bone_names)
    heads = bone_heads(model, state)
    rotation = state.body_quat[:nbone]
    local = rotation.copy()  # a root without a joint: its rotation relative to the world
    local[model.joint_bone] = relative_rotations(model, state.body_quat)
    bones = {
        name: BonePose(head=heads[i], rotation=_canonical(rotation[i]), local=_canonical(local[i]))
        for i, name in enumerate(model.bone_names)
    }
    return Keyframe(time=state.time, label=label, bones=bones, extra=extra)


def _canonical(q: np.ndarray) -> np.ndarray:
    """The quaternion with w ≥ 0 (q and −q are the same rotation)."""
    return -q if q[0] < 0.0 else q.copy()


class Runner:
    """Steps a model through a script, writing the trace and collecting keys."""

    def __init__(
        self,
        model: Model,
        trace: TraceWriter | None = None,
        trace_every: int = 1,
        on_step: Callable[[State], None] | None = None,
    ) -> None:
        self.model = model
        self.trace = trace
        self.trace_every = trace_every
        self.on_step = on_step
        self.state = initial_state(model)
        self.keys = KeyframeSet()

    def run(self, script: Script) -> RunResult:
        """Run every action, then wait out the script's duration."""
        start = time.perf_counter()
        error = None
        try:
            for action in script.actions:
                self._do(action)
            if script.duration is not None:
                self.advance(script.duration - self.state.time, None)
        except SimulationError as exc:
            error = exc
        wall = time.perf_counter() - start
        return RunResult(self.keys, self.state, self.state.step, wall, error)

    def _do(self, action) -> None:
        if isinstance(action, Push):
            self.advance(action.duration, action)
        elif isinstance(action, Wait):
            self.advance(action.duration, None)
        elif isinstance(action, Key):
            self.keys.add(capture(self.model, self.state, action.label, {"line": action.line}))
        else:  # pragma: no cover - the script parser only produces the types above
            raise TypeError(f"unknown action {action!r}")

    def advance(self, duration: float, push: Push | None) -> None:
        """Step until ``duration`` seconds have passed (nothing to do when ≤ 0)."""
        h = self.model.options.h
        t_end = self.state.time + duration
        while self.state.time < t_end - 0.5 * h:
            inp = push_input(self.model, self.state, push) if push is not None else None
            self.state, report = step(self.model, self.state, inp)
            self._record(report)

    def _record(self, report: StepReport) -> None:
        if self.on_step is not None:
            self.on_step(self.state)
        if self.trace is None or self.state.step % self.trace_every:
            return
        m, s = self.model, self.state
        self.trace.write_step(
            s.time,
            joint_rotation=joint_rotations(m, s),
            joint_elastic=s.joint_q_sf,
            joint_torque=s.joint_torque,
            bone_head=bone_heads(m, s),
            bone_tail=bone_tails(m, s),
            bone_quat=s.body_quat[: len(m.bone_names)],
            stats=dict(
                rows=report.rows,
                contacts=report.contacts,
                iterations=report.iterations,
                residual=report.residual,
                solver=report.solver,
            ),
        )


def trace_writer(path, model: Model) -> TraceWriter:
    """A trace writer for this model's skeleton."""
    return TraceWriter(path, model.bone_names, list(model.bone_parent), model.joint_names)
