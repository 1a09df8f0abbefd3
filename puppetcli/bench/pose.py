"""``puppetcli bench --pose``: a scripted pose's run against the bare in-place stepper.

The run is the CLI's (``Runner`` on rigs/doll.yaml and scripts/wave.yaml: the script's
actions, the pointer's pose for every step, the haptic chain, the keys), without the
trace; "with trace" adds the trace ``pose`` writes by default.  The bare stepper steps
the same model through the same inputs, recorded from one run, with nothing else
around it, so the ratio is what a script run costs beyond the solver.  Every timing is
the best of ``repeats`` runs, taken in turn round by round.
"""

from __future__ import annotations

import math
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from puppetcli.bench.scenes import ROOT
from puppetcli.rig.load import load_rig
from puppetcli.run.runner import Runner, script_model
from puppetcli.run.trace import RunTrace
from puppetcli.run.warmup import freeze_loaded
from puppetcli.script.load import Script, load_script
from solver.engine import Engine
from solver.model import Model, build_model
from solver.state import StepInput

RIG, SCRIPT = ROOT / "rigs" / "doll.yaml", ROOT / "scripts" / "wave.yaml"


@dataclass(frozen=True)
class PoseRow:
    """One configuration: steps per run, best wall seconds, steps/s, ratio to bare."""

    label: str
    h: float
    steps: int
    seconds: float
    steps_per_s: float
    ratio: float


def recorded_inputs(model: Model, plan: Script) -> list[StepInput]:
    """The input of every step of a run of ``plan`` (the inputs a run makes, here made
    step by step)."""
    runner = Runner(model, plan)
    runner.batch_steps = False
    inputs: list[StepInput] = []
    advance = runner.sim.advance

    def record(inp: StepInput | None = None) -> None:
        inputs.append(inp)
        advance(inp)

    runner.sim.advance = record
    runner.run()
    return inputs


def _bare(model: Model, inputs: list[StepInput]) -> float:
    sim = Engine(model).stepper()
    start = time.perf_counter()
    for inp in inputs:
        sim.advance(inp)
    return time.perf_counter() - start


def _scripted(model: Model, plan: Script, trace_dir: Path | None) -> float:
    runner = Runner(model, plan)
    if trace_dir is None:
        return runner.run().wall_time
    with RunTrace(trace_dir / "trace.mcap", model, plan, 1, runner.pointer_on) as trace:
        runner.trace = trace
        return runner.run().wall_time


def measure_pose(steps_h: list[float | None], repeats: int = 15) -> list[PoseRow]:
    """Rows for the example pose at each step h (None: the script's own)."""
    spec = load_rig(RIG)
    rows = []
    for h in steps_h:
        plan = load_script(SCRIPT, spec)
        model = script_model(build_model(spec), plan)
        rows += _measure(model if h is None else model.with_options(h=h), plan, repeats)
    return rows


def _measure(model: Model, plan: Script, repeats: int) -> list[PoseRow]:
    inputs = recorded_inputs(model, plan)
    freeze_loaded()  # as ``pose`` does once its solver is loaded
    with tempfile.TemporaryDirectory() as tmp:
        runs = {
            "bare stepper": lambda: _bare(model, inputs),
            "pose, no trace": lambda: _scripted(model, plan, None),
            "pose, trace": lambda: _scripted(model, plan, Path(tmp)),
        }
        best = dict.fromkeys(runs, math.inf)
        for _ in range(repeats):
            for label, run in runs.items():
                best[label] = min(best[label], run())
    n, h, bare = len(inputs), model.options.h, best["bare stepper"]
    return [PoseRow(label, h, n, t, n / t, bare / t) for label, t in best.items()]


def format_pose(rows: list[PoseRow]) -> str:
    """The rows as a table."""
    lines = [
        f"scripted pose: {RIG.relative_to(ROOT)} {SCRIPT.relative_to(ROOT)} "
        "(best of the runs; ratio: steps/s over the bare stepper's)",
        f"{'run':<16} {'h (s)':>7} {'steps':>6} {'wall (s)':>9} {'steps/s':>9} {'ratio':>6}",
    ]
    for r in rows:
        lines.append(
            f"{r.label:<16} {r.h:>7g} {r.steps:>6} {r.seconds:>9.3f} "
            f"{r.steps_per_s:>9,.0f} {r.ratio:>6.2f}"
        )
    return "\n".join(lines)
