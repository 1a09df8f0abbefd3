"""Timing of the numpy step against the compiled step on one scene, in one process.

The scene (issue 6): the doll at its options' h with gravity and ground contacts, its
left forearm pushed up with 60 N for 0.3 s (as ``puppetcli.bench.solvers``), and its right
hand gripped by the 6-DOF coupling while the pointer lifts it 0.2 m and draws it
0.1 m forward over 0.5 s.  The input sequence is recorded once from a compiled run
and replayed to both steps, so both time exactly the same work; each is timed
``repeats`` times and the best run counts (other processes only ever slow a run down).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from solver import quat
from solver.compiled.clock import STAGES, counter_read_seconds, seconds_per_cycle
from solver.compiled.layout import IOpt
from solver.engine import Engine
from solver.model import Model
from solver.observe import bone_points
from solver.rows.grip import Pointer, make_coupling
from solver.state import State, StepInput, initial_state

PUSH_BONE, PUSH_FORCE, PUSH_POINT, PUSH_TIME = "forearm_l", (0.0, 60.0, 0.0), (0.25, 0, 0), 0.3
GRIP_BONE, LIFT, LIFT_TIME = "hand_r", (0.0, 0.2, 0.1), 0.5
GAINS = dict(
    stiffness=2000.0,
    damping=20.0,
    rot_stiffness=20.0,
    rot_damping=0.5,
    force_limit=40.0,
    torque_limit=2.0,
)


@dataclass(frozen=True)
class Timing:
    """steps: per run; *_rate: steps/s (best of the repeats); ratio = fast/numpy;
    rows, contacts: means over the run; solvers: how often each solver ran."""

    steps: int
    numpy_rate: float
    fast_rate: float
    ratio: float
    rows: float
    contacts: float
    solvers: dict


def scene_inputs(model: Model, steps: int) -> tuple[State, list[StepInput]]:
    """The start state and the input of every step (recorded along a compiled run)."""
    h = model.options.h
    state = initial_state(model)
    b = model.bone_names.index(GRIP_BONE)
    start = bone_points(model, state, model.bone_tail0[b][None], bones=np.array([b]))[0]
    still = Pointer(start, quat.IDENTITY.copy(), np.zeros(3), np.zeros(3))
    coupling = make_coupling(state, still, b, start, **GAINS)
    pushed = model.bone_names.index(PUSH_BONE)
    local = model.bone_head0[pushed] - model.body_pos0[pushed] + np.array(PUSH_POINT)
    inputs, s, engine = [], state, Engine(model)
    for _ in range(steps):
        frac = min((s.time + h) / LIFT_TIME, 1.0)
        moving = s.time + 0.5 * h < LIFT_TIME
        vel = np.array(LIFT) / LIFT_TIME if moving else np.zeros(3)
        ptr = Pointer(start + frac * np.array(LIFT), quat.IDENTITY.copy(), vel, np.zeros(3))
        force = torque = None
        if s.time < PUSH_TIME:
            force, torque = np.zeros((model.nbody, 3)), np.zeros((model.nbody, 3))
            force[pushed] = PUSH_FORCE
            torque[pushed] = quat.cross(quat.rotate(s.body_quat[pushed], local), force[pushed])
        inputs.append(StepInput(force, torque, ptr, coupling))
        s, _ = engine.step(s, inputs[-1])
    return state, inputs


def _run(engine: Engine, state: State, inputs: list[StepInput]) -> tuple[float, list]:
    reports = []
    start = time.perf_counter()
    for inp in inputs:
        state, report = engine.step(state, inp)
        reports.append(report)
    return time.perf_counter() - start, reports


def compare(model: Model, seconds: float = 0.5, repeats: int = 3) -> Timing:
    """Best-of-``repeats`` steps/s of solver.pipeline.step and fast_step over ``seconds``."""
    n = max(1, round(seconds / model.options.h))
    state, inputs = scene_inputs(model, n)
    numpy, compiled = Engine(model.with_options(engine="numpy")), Engine(model)
    slow = min(_run(numpy, state, inputs)[0] for _ in range(repeats))
    fast, reports = min(
        (_run(compiled, state, inputs) for _ in range(repeats)), key=lambda run: run[0]
    )
    solvers: dict[str, int] = {}
    for r in reports:
        solvers[r.solver] = solvers.get(r.solver, 0) + 1
    return Timing(
        n,
        n / slow,
        n / fast,
        slow / fast,
        float(np.mean([r.rows for r in reports])),
        float(np.mean([r.contacts for r in reports])),
        solvers,
    )


def first_call_seconds(model: Model) -> float:
    """Wall time of one compiled step; in a fresh process this is the compile or the
    cache load."""
    start = time.perf_counter()
    Engine(model).step(initial_state(model))
    return time.perf_counter() - start


def stage_profile(
    model: Model, state: State, inputs: list[StepInput], repeats: int = 3
) -> dict[str, float]:
    """Microseconds per step of each stage of the compiled step (solver.compiled.clock.STAGES,
    read from the processor's cycle counter inside the step) over ``inputs``, plus the
    rest of an unprofiled step's wall time: argument passing and fast_step's own Python
    (and the substeps of a subdivided step, which run on their own model).

    Reading the counter costs ~25 ns here; one read's cost, timed in a compiled loop, is
    taken off each stage once per step (twice for the collision stage, which spans two
    reads).  A profiled step still runs a few µs slower than an unprofiled one (~7 µs on
    the doll): the stages absorb that.  Each figure is the best of ``repeats`` runs."""
    engine = Engine(model)
    fm = engine.packed
    prof = fm.ws.cycles
    engine.step(state, inputs[0])  # compiled and cached before the count starts
    per_cycle, read = seconds_per_cycle(), counter_read_seconds()
    n = len(inputs)
    stages = {name: math.inf for name in STAGES}
    wall = math.inf
    for _ in range(repeats):
        wall = min(wall, _run(engine, state, inputs)[0] / n * 1e6)
        prof[:] = 0
        fm.iopt[IOpt.profiling] = 1
        try:
            _run(engine, state, inputs)
        finally:
            fm.iopt[IOpt.profiling] = 0
        for k, name in enumerate(STAGES):
            reads = 2 if k == 3 else 1
            us = float(prof[k]) * per_cycle / n * 1e6 - reads * read * 1e6
            stages[name] = min(stages[name], max(us, 0.0))
    stages["call and Python (fast_step)"] = max(wall - sum(stages.values()), 0.0)
    return stages
