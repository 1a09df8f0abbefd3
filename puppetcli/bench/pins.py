"""The cost of pins: the grip scene of ``puppetcli.bench.skips`` (the doll's right hand lifted
along a minimum-jerk path) with 0, 1 and 4 pins, interleaved, best of ``repeats``.

Pins (solver.rows.pin), made at rest: 1 = the head whole (6 rows); 4 = the head and both
feet whole and the left hand's centre (21 rows).  Their rows are iterated by the hybrid
solve (the exact tree has no pin nodes), so a pinned doll always runs the hybrid; 0 pins
is the doll as it runs without them: no rows, no branch beyond an empty tuple's test.
Each row gives steps/s on the compiled step, the ratio to 0 pins, the mean row count and
iterations, and how far the pinned points moved at most (m).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace

import numpy as np

from puppetcli.bench.scenes import grip_inputs
from puppetcli.bench.solvers import doll_scenes
from solver import quat
from solver.engine import Engine
from solver.model import Model
from solver.rows.pin import make_pin
from solver.state import StepInput, initial_state

PIN_SETS = {
    0: (),
    1: (("head", True),),
    4: (("head", True), ("foot_l", True), ("foot_r", True), ("hand_l", False)),
}


@dataclass(frozen=True)
class PinRow:
    """One pin count: steps/s, ÷ 0 pins, mean rows and iterations, the solvers used and
    the pinned points' largest drift (m)."""

    pins: int
    steps_per_s: float
    ratio: float
    rows: float
    iterations: float
    solvers: str
    drift: float


def pinned_inputs(model: Model, inputs: list[StepInput], count: int) -> list[StepInput]:
    """``inputs`` with the pins of PIN_SETS[count], made at rest."""
    state = initial_state(model)
    names = model.bone_names
    pins = tuple(make_pin(state, names.index(b), orient=o) for b, o in PIN_SETS[count])
    return [replace(inp, pins=pins) for inp in inputs]


def _run(model: Model, inputs: list[StepInput]) -> tuple[float, list, float]:
    """(wall seconds, reports, largest drift of a pinned point) of one run from rest."""
    engine, state, reports, drift = Engine(model), initial_state(model), [], 0.0
    start = time.perf_counter()
    for inp in inputs:
        state, report = engine.step(state, inp)
        reports.append(report)
    wall = time.perf_counter() - start
    for pin in inputs[-1].pins if inputs else ():
        where = state.body_pos[pin.bone] + quat.rotate(state.body_quat[pin.bone], pin.point)
        drift = max(drift, float(np.linalg.norm(where - pin.target)))
    return wall, reports, drift


def measure_pins(h: float = 0.001, seconds: float = 0.5, repeats: int = 5) -> list[PinRow]:
    """PinRows for 0, 1 and 4 pins (module docstring)."""
    model = doll_scenes()["doll"].with_options(h=h)
    n = max(1, round(seconds / h))
    base = grip_inputs(model, seconds, n)
    runs = {count: pinned_inputs(model, base, count) for count in PIN_SETS}
    for inputs in runs.values():  # untimed: compile, warm caches
        _run(model, inputs[:5])
    best = dict.fromkeys(runs, math.inf)
    last: dict = {}
    for _ in range(repeats):
        for count, inputs in runs.items():
            wall, reports, drift = _run(model, inputs)
            best[count], last[count] = min(best[count], wall), (reports, drift)
    rows = []
    for count in runs:
        reports, drift = last[count]
        solvers = "+".join(sorted({r.solver for r in reports}))
        rows_mean = float(np.mean([r.rows for r in reports]))
        sweeps = float(np.mean([r.iterations for r in reports]))
        rows.append(PinRow(count, n / best[count], best[0] / best[count], rows_mean, sweeps,
                           solvers, drift))  # fmt: skip
    return rows


def format_pins(rows: list[PinRow], h: float) -> str:
    head = (
        f"{'pins':>4} {'steps/s':>9} {'× 0 pins':>8} {'rows':>6} {'iterations':>10} "
        f"{'solver':<14} {'drift (m)':>9}"
    )
    lines = [f"pins at h = {h:g} s (the grip scene on the doll, compiled step)", head,
             "-" * len(head)]  # fmt: skip
    for r in rows:
        lines.append(
            f"{r.pins:>4} {r.steps_per_s:>9,.0f} {r.ratio:>8.2f} {r.rows:>6.1f} "
            f"{r.iterations:>10.1f} {r.solvers:<14} {r.drift:>9.1e}"
        )
    return "\n".join(lines)
