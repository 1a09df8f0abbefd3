"""Benchmarks: steps per second of the solvers on the doll, in one run.

Speed is reported as ratios measured in the same run, never as an absolute pass/fail:
against the paper's setting on the numpy step (PGS, 15 iterations, warm start; the
readable reference implementation, ``solver.pipeline.step``) and, with ``--peers``, against
MuJoCo on the same rig and scene (``puppetcli.bench.peers.doll_timer``).  Every solver runs
on the compiled step (``solver.Engine``'s default); the numpy step is
measured only for the baseline unless asked, since it is ~40× slower and its other
solvers say nothing about the CLI.

Engines: ``fast`` is ``Engine.step`` on the compiled step (a new State every step);
``sim`` is ``Engine.stepper()``, the same kernel stepping its own arrays in place (as
MuJoCo's mj_step steps mjData: what the CLI's runs use); ``numpy`` is the numpy step
(``Options.engine = "numpy"``, solver.pipeline) stepped in place.

The scene (``run_timer``): the doll standing on its stand, its left forearm's end
gripped (position only, ``GRIP``) and lifted by ``LIFT`` along a minimum-jerk path over
``seconds``.  Each configuration first takes a few untimed steps (JIT compilation,
caches), then is timed from rest ``repeats`` times; the best run counts (other
processes only ever slow a run down).  Repeats are chosen so that every configuration
times enough steps to be steady (``MIN_TIMED_STEPS``), as MuJoCo's runs are, and the
runs of all configurations at one scene and step are interleaved, round by round, so a
machine whose speed drifts (a shared 2-core VM does, by up to ~1.5× over seconds)
slows every configuration alike and the ratios stay honest.
"""

from __future__ import annotations

import csv
import io
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, replace

from puppetcli.bench.scenes import RIGS, grip_inputs
from puppetcli.rig.load import load_rig
from solver.engine import Engine
from solver.errors import SimulationError
from solver.model import Model, build_model
from solver.state import StepInput, StepReport, initial_state

WARMUP_STEPS = 5
BASELINE = "pgs"  # on the numpy step
SOLVERS = ("pgs", "hybrid", "auto", "direct")
MIN_TIMED_STEPS = {"fast": 3000, "sim": 3000, "numpy": 100, "mujoco": 3000}
MIN_REPEATS = {"fast": 5, "sim": 5, "numpy": 1, "mujoco": 5}
MUJOCO_INTEGRATORS = ("Euler", "implicitfast")
NAN = math.nan
INSTALL_HINT = "peers: mujoco is not installed (pip install -e '.[bench]' to compare with MuJoCo)"


@dataclass(frozen=True)
class BenchRow:
    """One measured configuration.

    steps: per timed run; seconds: wall time of the best run; realtime: simulated
    seconds per wall second; ratio: steps/s ÷ numpy PGS's at the same scene and h;
    vs_mujoco: steps/s ÷ MuJoCo (Euler)'s at the same scene and h (nan: not measured);
    contacts, substeps: means per step."""

    scene: str
    h: float
    solver: str
    engine: str
    steps: int
    repeats: int
    seconds: float
    steps_per_s: float
    realtime: float
    ratio: float
    vs_mujoco: float = NAN
    contacts: float = 0.0
    substeps: float = 1.0
    note: str = ""


@dataclass(frozen=True)
class Timing:
    """One timed scene: steps per run, wall seconds of the best run, means per step."""

    steps: int
    seconds: float
    contacts: float
    substeps: float


def doll_scenes() -> dict[str, Model]:
    """`doll`: the full doll (ground contacts, limits); `doll-joints`: joints and rheology only."""
    spec = load_rig(RIGS / "doll.yaml")
    bare = replace(
        spec,
        ground=None,
        bones=tuple(replace(b, limits=type(b.limits)(), collide=False) for b in spec.bones),
    )
    return {"doll": build_model(spec), "doll-joints": build_model(bare)}


class _Stepping:
    """A run of ``Engine.step`` (a new State a step) from rest with the stepper's
    ``advance`` and ``contacts``/``substeps``, so one loop times every engine (the method
    call costs ~0.1 µs a step)."""

    def __init__(self, model: Model) -> None:
        self.engine, self.state = Engine(model), initial_state(model)
        self.last: StepReport | None = None

    def advance(self, inp: StepInput) -> None:
        self.state, self.last = self.engine.step(self.state, inp)

    @property
    def contacts(self) -> int:
        return self.last.contacts

    @property
    def substeps(self) -> int:
        return self.last.substeps


ENGINES = {
    "numpy": lambda model: Engine(model.with_options(engine="numpy")).stepper(),
    "fast": _Stepping,
    "sim": lambda model: Engine(model).stepper(),
}
"""engine → a run from rest of a model: an object with ``advance(inp)`` and the last
step's ``contacts`` and ``substeps`` (Sim's interface; for Sim the report is not made,
as MuJoCo's loop reads only d.ncon after mj_step)."""


def repeats_for(steps: int, engine: str) -> int:
    """How many timed runs of ``steps`` steps make a steady timing on ``engine``."""
    return max(MIN_REPEATS[engine], math.ceil(MIN_TIMED_STEPS[engine] / max(steps, 1)))


def run_timer(model: Model, seconds: float, engine: str = "fast"):
    """A function that times one run of the grip scene (``grip_inputs``, lift over
    ``seconds``) from rest on ``engine`` and returns its Timing.  Made once, here: the
    inputs, and WARMUP_STEPS untimed steps of them (compiling, filling caches)."""
    n = max(1, round(seconds / model.options.h))
    inputs = grip_inputs(model, seconds, n)
    start_run = ENGINES[engine]
    warm = start_run(model)
    for inp in inputs[:WARMUP_STEPS]:
        warm.advance(inp)

    def timed() -> Timing:
        sim, contacts, substeps = start_run(model), 0, 0
        start = time.perf_counter()
        for inp in inputs:
            sim.advance(inp)
            contacts += sim.contacts
            substeps += sim.substeps
        return Timing(n, time.perf_counter() - start, contacts / n, substeps / n)

    return timed


def measure(
    scenes: dict[str, Model],
    steps_h: list[float],
    solvers: list[str],
    seconds: float,
    engines: tuple[str, ...] = ("fast",),
    peers: bool = False,
) -> list[BenchRow]:
    """The numpy PGS baseline, then every (solver, engine), at every (scene, h); with
    ``peers``, MuJoCo's rows on the doll (see ``mujoco_rows``)."""
    rows = []
    for name, model in scenes.items():
        for h in steps_h:
            trials = [_ours(name, model, h, BASELINE, "numpy", seconds)]
            for solver in solvers:
                for engine in engines:
                    if (solver, engine) != (BASELINE, "numpy"):
                        trials.append(_ours(name, model, h, solver, engine, seconds))
            if peers and name == "doll":
                trials += [_mujoco(h, seconds, integrator) for integrator in MUJOCO_INTEGRATORS]
            here = _interleaved(trials)
            rows += _against_mujoco([_with_ratio(r, here[0]) for r in here])
    return rows


@dataclass
class Trial:
    """One configuration to time: ``run()`` times one run and returns its row (steps/s
    from that run); ``repeats`` runs are made, interleaved with the other trials'
    (``_interleaved``), and the fastest counts.  ``row`` is final when no run is due."""

    repeats: int
    run: Callable[[], BenchRow] | None  # None: the row is already final
    row: BenchRow | None = None


def _interleaved(trials: list[Trial]) -> list[BenchRow]:
    """The rows of ``trials``, their runs made round by round (module docstring); a trial
    whose run fails (a row without steps) stops there with that row."""
    for k in range(max(t.repeats for t in trials)):
        for t in trials:
            if t.run is None or k >= t.repeats:
                continue
            row = t.run()
            if not row.steps:
                t.row, t.run = row, None
            elif t.row is None or row.seconds < t.row.seconds:
                t.row = replace(row, repeats=t.repeats)
    return [t.row for t in trials]


def _with_ratio(row: BenchRow, base: BenchRow) -> BenchRow:
    """``row`` with its ratio to the baseline row (its steps/s ÷ the baseline's)."""
    return replace(row, ratio=row.steps_per_s / base.steps_per_s)


def _failed(name: str, h: float, solver: str, engine: str, note: str) -> BenchRow:
    return BenchRow(name, h, solver, engine, 0, 0, NAN, NAN, NAN, NAN, NAN, NAN, NAN, note)


def _ours(name: str, model: Model, h: float, solver: str, engine: str, seconds: float) -> Trial:
    """The trial of one of our (solver, engine) on the grip scene (``run_timer``)."""
    if solver == "direct" and (model.has_collision or model.has_limits):
        return Trial(
            0, None, _failed(name, h, solver, engine, "n/a: direct needs two-sided rows only")
        )
    if engine != "numpy" and solver == "reference":
        return Trial(0, None, _failed(name, h, solver, engine, "n/a: numpy only"))
    m = model.with_options(h=h, method=solver, iterations=15, warm_start=True)
    span = seconds if solver != "reference" else min(seconds, 20 * h)

    def failed(exc: SimulationError) -> BenchRow:
        return _failed(name, h, solver, engine, f"failed: {str(exc)[:60]}")

    try:
        timed = run_timer(m, span, engine)
    except SimulationError as exc:
        return Trial(0, None, failed(exc))

    def run() -> BenchRow:
        try:
            t = timed()
        except SimulationError as exc:
            return failed(exc)
        return BenchRow(name, h, solver, engine, t.steps, 1, t.seconds, t.steps / t.seconds,
                        t.steps * h / t.seconds, NAN, contacts=t.contacts,
                        substeps=t.substeps)  # fmt: skip

    return Trial(repeats_for(max(1, round(span / h)), engine), run)


def _mujoco(h: float, seconds: float, integrator: str) -> Trial:
    """The trial of MuJoCo with ``integrator`` on the same doll scene
    (``puppetcli.bench.peers.doll_timer``); engine "mujoco"."""
    from puppetcli.bench import peers

    n = max(1, round(seconds / h))
    if n < peers.WARMUP_STEPS:  # doll_timer warms up on the run's own inputs
        note = f"n/a: MuJoCo's run needs ≥ {peers.WARMUP_STEPS} steps"
        return Trial(0, None, _failed("doll", h, integrator.lower(), "mujoco", note))

    timed = peers.doll_timer(h, seconds, integrator)

    def run() -> BenchRow:
        r = timed()
        return BenchRow("doll", h, integrator.lower(), "mujoco", r["steps"], 1, r["seconds"],
                        r["steps_per_s"], r["steps"] * h / r["seconds"], NAN,
                        contacts=r["contacts"],
                        note="diverged" if r["diverged"] else "")  # fmt: skip

    return Trial(repeats_for(n, "mujoco"), run)


def _against_mujoco(rows: list[BenchRow]) -> list[BenchRow]:
    """Fill vs_mujoco (÷ MuJoCo Euler at the same scene and h) when it was measured."""
    ref = [r for r in rows if r.engine == "mujoco" and r.solver == "euler" and not r.note]
    if not ref:
        return rows
    return [replace(r, vs_mujoco=r.steps_per_s / ref[0].steps_per_s) for r in rows]


def format_table(rows: list[BenchRow]) -> str:
    """A fixed-width table of the rows (nan shown as -)."""
    head = (
        f"{'scene':<12} {'h (s)':>6} {'solver':<12} {'engine':<6} {'steps':>6} {'runs':>4} "
        f"{'steps/s':>9} {'× real':>7} {'× np pgs':>8} {'÷ mj':>6} {'contacts':>8} "
        f"{'subst':>5}  note"
    )
    lines = [head, "-" * len(head)]
    for r in rows:
        lines.append(
            f"{r.scene:<12} {r.h:>6g} {r.solver:<12} {r.engine:<6} {r.steps:>6} {r.repeats:>4} "
            f"{_num(r.steps_per_s, 9, ',.0f')} {_num(r.realtime, 7, '.1f')} "
            f"{_num(r.ratio, 8, '.2f')} {_num(r.vs_mujoco, 6, '.2f')} "
            f"{_num(r.contacts, 8, '.1f')} {_num(r.substeps, 5, '.2f')}  {r.note}"
        )
    return "\n".join(lines)


def _num(x: float, width: int, spec: str) -> str:
    return f"{'-':>{width}}" if not math.isfinite(x) else f"{x:>{width}{spec}}"


def peer_summary(rows: list[BenchRow]) -> list[str]:
    """One line per (h, our compiled solver) on the doll: ours ÷ each MuJoCo integrator."""
    lines = []
    for h in dict.fromkeys(r.h for r in rows):
        here = [r for r in rows if r.scene == "doll" and r.h == h and math.isfinite(r.steps_per_s)]
        mj = [r for r in here if r.engine == "mujoco"]
        for ours in (r for r in here if r.engine in ("fast", "sim")):
            vs = ", ".join(
                f"{ours.steps_per_s / m.steps_per_s:.2f}× MuJoCo {m.solver} "
                f"({m.steps_per_s:,.0f}{', diverged' if m.note else ''})"
                for m in mj
            )
            if vs:
                lines.append(
                    f"doll h={h:g}: {ours.solver} ({ours.engine}) {ours.steps_per_s:,.0f} steps/s"
                    f" = {vs}"
                )
    return lines


def stage_table(rows: dict[str, float]) -> str:
    """Where the time goes: ``{stage: microseconds per step}`` as a table with each
    stage's share of the total (``doll_stages``: the compiled step's own profiler)."""
    total = sum(rows.values())
    head = f"{'stage':<40} {'µs/step':>9} {'share':>6}"
    lines = [head, "-" * len(head)]
    for name, us in rows.items():
        share = us / total if total > 0 else NAN
        lines.append(f"{name:<40} {us:>9.2f} {_num(100 * share, 5, '.1f')}%")
    lines.append(f"{'total':<40} {total:>9.2f} {_num(100.0 if total > 0 else NAN, 5, '.1f')}%")
    return "\n".join(lines)


def csv_text(rows: list[BenchRow]) -> str:
    """The rows as CSV (every field; nan as ``nan``)."""
    fields = list(BenchRow.__dataclass_fields__)
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(fields)
    writer.writerows([getattr(r, f) for f in fields] for r in rows)
    return out.getvalue()


def doll_stages(h: float, seconds: float) -> dict[str, float]:
    """µs per step of each stage of the compiled step on the doll grip scene (auto)."""
    from puppetcli.bench.stages import stage_profile

    model = doll_scenes()["doll"].with_options(h=h, method="auto")
    inputs = grip_inputs(model, seconds, max(1, round(seconds / h)))
    return stage_profile(model, initial_state(model), inputs)
