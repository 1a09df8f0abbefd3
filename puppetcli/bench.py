"""Benchmarks: steps per second of the solvers on example scenes, in one run.

Speed is reported as a ratio against a baseline measured in the same run (the
paper's setting: PGS, 15 iterations, warm start, on the numpy step), never as an
absolute pass/fail.  Each solver runs on both engines: `numpy` (solver.step.step,
the readable reference implementation) and `fast` (solver.fast.fast_step, the
compiled step the CLI uses).
Each configuration first takes a few untimed steps (JIT compilation, caches),
then is timed over a fixed simulated duration.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from puppetcli.pointer import Motion, pointer_over_step
from puppetcli.rigfile import load_rig
from solver import quat
from solver.errors import SimulationError
from solver.fast import fast_step
from solver.grip import make_coupling
from solver.model import Model, build_model
from solver.state import StepInput, initial_state
from solver.step import step

RIGS = Path(__file__).resolve().parent.parent / "rigs"
WARMUP_STEPS = 5
BASELINE = "pgs"


@dataclass(frozen=True)
class BenchRow:
    """One measured configuration."""

    scene: str
    h: float
    solver: str
    engine: str
    steps: int
    seconds: float
    steps_per_s: float
    ratio: float
    contacts: float
    note: str = ""


def doll_scenes() -> dict[str, Model]:
    """`doll`: the full doll (ground contacts, limits); `doll-joints`: joints and rheology only."""
    spec = load_rig(RIGS / "doll.yaml")
    bare = replace(
        spec,
        ground=None,
        bones=tuple(replace(b, limits=type(b.limits)(), collide=False) for b in spec.bones),
    )
    return {"doll": build_model(spec), "doll-joints": build_model(bare)}


GRIP = dict(  # the script's default gains, position-only (as for pulls)
    stiffness=2000.0, damping=40.0, rot_stiffness=50.0, rot_damping=2.0,
    force_limit=300.0, torque_limit=30.0, position_only=True,
)  # fmt: skip
LIFT = np.array([0.0, 0.15, 0.15])  # m: where the grip takes the forearm's end


ENGINES = {"numpy": step, "fast": fast_step}


def time_run(model: Model, seconds: float, engine: str = "numpy") -> tuple[int, float, float]:
    """(steps, wall seconds, mean contacts): the doll standing on the ground while a grip
    lifts its left forearm's end along a minimum-jerk path over ``seconds``."""
    step_fn = ENGINES[engine]
    state = initial_state(model)
    for _ in range(WARMUP_STEPS):
        state, _ = step_fn(model, state)
    state = initial_state(model)
    b = model.bone_names.index("forearm_l")
    end = model.bone_tail0[b]
    motion = Motion(0.0, seconds, end, quat.IDENTITY, LIFT, np.zeros(3))
    coupling = make_coupling(state, pointer_over_step(motion, 0.0, 1.0, 0.0), b, end, **GRIP)
    h = model.options.h
    n = max(1, round(seconds / h))
    # The pointer's path depends on time only: made before the clock starts, so the
    # timing is the step's (the runner's own per-step Python adds ~80 µs; see README).
    inputs = [
        StepInput(pointer=pointer_over_step(motion, k * h, h, 0.0), coupling=coupling)
        for k in range(n)
    ]
    contacts = 0
    start = time.perf_counter()
    for inp in inputs:
        state, report = step_fn(model, state, inp)
        contacts += report.contacts
    return n, time.perf_counter() - start, contacts / n


def measure(
    scenes: dict[str, Model], steps_h: list[float], solvers: list[str], seconds: float
) -> list[BenchRow]:
    """Every (scene, h, solver, engine), with the ratio to numpy PGS at the same scene and h."""
    rows = []
    for name, model in scenes.items():
        for h in steps_h:
            base = None
            for solver in [BASELINE] + [s for s in solvers if s != BASELINE]:
                for engine in ENGINES:
                    row = _measure_one(name, model, h, solver, engine, seconds, base)
                    base = row.steps_per_s if base is None else base
                    rows.append(row)
    return rows


def _measure_one(
    name: str, model: Model, h: float, solver: str, engine: str, seconds: float, base
) -> BenchRow:
    if solver == "direct" and (model.has_collision or model.has_limits):
        return BenchRow(name, h, solver, engine, 0, 0.0, 0.0, 0.0, 0.0, "n/a: contacts/limits")
    if engine == "fast" and solver == "reference":
        return BenchRow(name, h, solver, engine, 0, 0.0, 0.0, 0.0, 0.0, "n/a: numpy only")
    m = model.with_options(h=h, method=solver, iterations=15, warm_start=True)
    span = seconds if solver != "reference" else min(seconds, 20 * h)
    try:
        n, wall, contacts = time_run(m, span, engine)
    except SimulationError as exc:
        return BenchRow(name, h, solver, engine, 0, 0.0, 0.0, 0.0, 0.0, str(exc)[:60])
    rate = n / wall
    return BenchRow(name, h, solver, engine, n, wall, rate, rate / (base or rate), contacts)


def format_table(rows: list[BenchRow]) -> str:
    """A fixed-width table of the rows."""
    head = (
        f"{'scene':<12} {'h (s)':>7} {'solver':<10} {'engine':<6} {'steps':>6} {'steps/s':>10} "
        f"{'× numpy pgs':>11} {'contacts':>8}  note"
    )
    lines = [head, "-" * len(head)]
    for r in rows:
        lines.append(
            f"{r.scene:<12} {r.h:>7g} {r.solver:<10} {r.engine:<6} {r.steps:>6} "
            f"{r.steps_per_s:>10,.0f} {r.ratio:>11.2f} {r.contacts:>8.1f}  {r.note}"
        )
    return "\n".join(lines)


def csv_text(rows: list[BenchRow]) -> str:
    """The rows as CSV."""
    fields = list(BenchRow.__dataclass_fields__)
    out = [",".join(fields)]
    out += [",".join(str(getattr(r, f)) for f in fields) for r in rows]
    return "\n".join(out) + "\n"
