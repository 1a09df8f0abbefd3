"""Work-precision study: error against run time of each solver setting and step.

Scenes, their error measures and references: ``puppetcli.bench.scenes``
(``creep`` against its exact solution; ``chain-1s`` / ``chain-3s``, the tip of a 10-link
chain after 1 s and 3 s of one run; ``doll``, every bone's head at 0.5, 1.0, 1.5 s of a
grip lifting the doll's forearm).  Settings: PGS with 5/15/50 sweeps × warm start off,
on, ×0.7 (the reference implementation's factor); direct; auto; hybrid with 15 and 50
sweeps; each at h = 1, 5, 20 ms.  The baseline is the paper's setting ``pgs15-ws``.
``--peers`` adds MuJoCo's rows (``puppetcli.bench.precision_peers``).

Every run uses the compiled step in place (solver.compiled.sim.Sim: fast_step's kernel and
states, bit for bit, without its per-step Python; ``puppetcli.bench.scenes.run_scene``).
Time is the wall time of the steps (time.perf_counter; reading a sample's state is not
timed, as in the MuJoCo rows), the best of several runs after an untimed warm-up run
that compiles the kernels for the configuration: as many runs as make a steady timing
(``puppetcli.bench.solvers.repeats_for``, the rule of ``bench``'s table: at least 5 runs and
3,000 timed steps, so a 75-step doll run at 20 ms is timed 40 times), the same rule for
the MuJoCo rows; ``--quick`` times one run (a study given ``repeats`` times that many).
The runs of every setting at one scene and step are interleaved round by round, as in
``bench``'s table: the shared machine's speed drifts by up to ~1.5× within a minute,
and so the time ratios between them are measured in the same phase.
Times are only comparable within one run of the study (DESIGN.md: speed is measured as
ratios): ``time_ratio`` is a row's seconds ÷ the baseline's at the same scene and h in
the same run.  A setting that cannot run a scene (direct with contacts) is a row with
``note`` "n/a …"; one whose run breaks down has error nan and note "unstable …".
"""

from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from puppetcli.bench import scenes as ps
from puppetcli.bench.precision_row import BASELINE, PrecisionRow
from puppetcli.bench.scenes import KINDS
from puppetcli.bench.solvers import repeats_for
from puppetcli.outputs import atomic_path, write_text_atomic
from solver.errors import SimulationError
from solver.model import Model

NAN = math.nan


@dataclass(frozen=True)
class Setting:
    """One solver setting: Options fields method, iterations, warm_start(_factor)."""

    name: str
    method: str
    iterations: int = 15
    warm_start: bool = True
    warm_start_factor: float = 1.0


def _pgs(n: int, ws: bool, factor: float = 1.0) -> Setting:
    tag = f"pgs{n}" + ("" if not ws else "-ws" if factor == 1.0 else f"-ws{factor:g}")
    return Setting(tag, "pgs", n, ws, factor)


SETTINGS = [
    *(_pgs(n, ws, f) for n in (5, 15, 50) for ws, f in ((False, 1.0), (True, 1.0), (True, 0.7))),
    Setting("direct", "direct"),
    Setting("auto", "auto"),
    Setting("hybrid15", "hybrid", 15),
    Setting("hybrid50", "hybrid", 50),
]
QUICK_SETTINGS = [s for s in SETTINGS if s.name in ("pgs5", BASELINE, "direct", "auto", "hybrid15")]
STEPS_H = [0.001, 0.005, 0.02]
QUICK_STEPS_H = [0.005, 0.02]
ROW_KIND = {"creep": "creep", "chain-1s": "chain", "chain-3s": "chain", "doll": "doll"}
ROW_SCENES = tuple(ROW_KIND)  # the rows' scene names, in table order
EQUAL_TIME = ("auto", "direct")  # settings given equal-time runs (equal_time_rows)
GRID = 0.5  # s: every scene's sample times (creep 2, 6; chain 1, 3; doll 0.5, 1, 1.5) are multiples
EQUAL_TIME_NOTE = "equal-time run"
REPLANNED_NOTE = "equal-time run, re-planned"
EQUAL_TIME_BUDGET = 0.9
"""The share of the baseline's run time an equal-time run is planned to take.  The
verdict compares measured times (≤), and two runs of the same work differ by several
per cent on this machine, so a run planned at exactly the baseline's time lands above
it about half the time and says nothing; planned at 90 % it lands at or below it."""
REFERENCE_H = {"chain": 0.0001, "doll": 0.0001}
QUICK_REFERENCE_H = {"chain": 0.0005, "doll": 0.001}


def configure(model: Model, setting: Setting, h: float) -> Model:
    return model.with_options(
        h=h,
        method=setting.method,
        iterations=setting.iterations,
        warm_start=setting.warm_start,
        warm_start_factor=setting.warm_start_factor,
    )


def _timed(scenes: list[ps.Scene], repeats: int | None) -> list:
    """For each scene: (samples at the marks, the best wall seconds to each mark, mean
    substeps), or the SimulationError its run raised; ``repeats`` runs, or (None) as many
    as make a steady timing (module docstring), the scenes' runs interleaved round by
    round, so a drifting machine slows them alike and their ratios hold."""
    out: list = [None] * len(scenes)
    best = [np.full(len(sc.marks), math.inf) for sc in scenes]
    for k, sc in enumerate(scenes):
        out[k] = _attempt(replace(sc, inputs=sc.inputs[:10], marks=[]))  # compiles, warms
    runs = max(repeats or repeats_for(len(sc.inputs), "sim") for sc in scenes)
    for _ in range(runs):
        for k, sc in enumerate(scenes):
            if not isinstance(out[k], SimulationError):
                out[k] = _attempt(sc)
                if not isinstance(out[k], SimulationError):
                    best[k] = np.minimum(best[k], out[k][1])
    return [got if isinstance(got, SimulationError) else (got[0], b, got[2])
            for got, b in zip(out, best, strict=True)]  # fmt: skip


def _attempt(sc: ps.Scene):
    """ps.run_scene(sc), or the SimulationError it raised."""
    try:
        return ps.run_scene(sc)
    except SimulationError as exc:
        return exc


def _scene(kind: str, setting: Setting, h: float) -> tuple[ps.Scene, str]:
    """The scene for setting at h, and why it cannot run ("" when it can)."""
    model = configure(ps.base_model(kind), setting, h)
    sc = ps.scene(kind, model)
    if setting.method == "direct" and (model.has_collision or model.has_limits):
        return sc, "n/a: direct needs two-sided rows only"
    return sc, ""


def scene_rows(
    kind: str, settings: list[Setting], h: float, repeats: int | None, reference_h: dict
) -> list[PrecisionRow]:
    """The rows of one scene kind for every setting at step h, their runs timed together
    (``_timed``: interleaved, so the time ratios between them are the same phase's)."""
    prepared = [(s, *_scene(kind, s, h)) for s in settings]
    runnable = [(s, sc) for s, sc, why in prepared if not why]
    timed = dict(zip((s.name for s, _ in runnable), _timed([sc for _, sc in runnable], repeats),
                     strict=True))  # fmt: skip
    rows = []
    for s, sc, why in prepared:
        if why:
            rows += [_empty(name, sc, s, h, why) for name, _ in sc.rows]
        else:
            rows += _measured_rows(kind, sc, s, h, timed[s.name], reference_h)
    return rows


def _measured_rows(kind, sc, setting, h, timed, reference_h, note="", beside=NAN):
    """The rows of a timed run of ``sc`` (``_timed``'s): its errors against the scene's
    reference, or unstable rows when its run broke down."""
    if isinstance(timed, SimulationError):
        return _unstable(sc, setting, h, timed)
    got, walls, substeps = timed
    ref, ref_errors = ps.reference(kind, h, reference_h.get(kind, 0.0))
    dist = ps.distances(got, ref)
    rows = []
    for name, ix in sc.rows:
        steps, wall = sc.marks[ix[-1]], float(walls[ix[-1]])
        rows.append(PrecisionRow(name, setting.name, h, steps, wall, steps / wall,
                                 steps * h / wall, float(dist[list(ix)].max()), sc.unit,
                                 ref_error=ref_errors[name], substeps=substeps, note=note,
                                 beside=beside))  # fmt: skip
    return rows


def _unstable(sc: ps.Scene, setting: Setting, h: float, exc: Exception) -> list[PrecisionRow]:
    return [_empty(name, sc, setting, h, f"unstable: {str(exc)[:50]}") for name, _ in sc.rows]


def _empty(name: str, sc: ps.Scene, setting: Setting, h: float, note: str) -> PrecisionRow:
    return PrecisionRow(name, setting.name, h, 0, NAN, NAN, NAN, NAN, sc.unit, note=note)


def with_time_ratios(rows: list[PrecisionRow]) -> list[PrecisionRow]:
    """Each row's time ÷ the baseline's at the same scene and h (an equal-time run's: at
    the h it was timed beside; nan without one)."""
    base = {(r.scene, r.h): r.seconds for r in rows if r.setting == BASELINE}

    def at(r: PrecisionRow) -> float:
        return r.h if math.isnan(r.beside) else r.beside

    return [replace(r, time_ratio=r.seconds / base.get((r.scene, at(r)), NAN)) for r in rows]


def study(
    *,
    quick: bool = False,
    scenes: tuple[str, ...] = KINDS,
    settings: list[Setting] | None = None,
    steps_h: list[float] | None = None,
    repeats: int | None = None,
    reference_h: dict[str, float] | None = None,
    peers: bool = False,
) -> list[PrecisionRow]:
    """Every (scene, setting, h) of the study; ``quick``: fewer settings and steps,
    coarser references.  ``peers``: MuJoCo's rows too (when it is installed)."""
    settings = settings or (QUICK_SETTINGS if quick else SETTINGS)
    steps_h = steps_h or (QUICK_STEPS_H if quick else STEPS_H)
    repeats = repeats or (1 if quick else None)  # None: steady timings (_timed)
    reference_h = {**(QUICK_REFERENCE_H if quick else REFERENCE_H), **(reference_h or {})}
    rows = []
    for kind in (k for k in KINDS if k in scenes):
        for h in steps_h:
            rows += scene_rows(kind, settings, h, repeats, reference_h)
    if not quick:
        rows += equal_time_rows(rows, settings, repeats, reference_h)
    if peers:
        from puppetcli.bench.precision_peers import peer_rows

        rows += peer_rows(tuple(k for k in scenes if k != "creep"), steps_h, quick, repeats)
    order = {name: i for i, name in enumerate(ROW_SCENES)}
    rows.sort(key=lambda r: order.get(r.scene, len(order)))  # stable: one block per scene
    return with_time_ratios(rows)


def equal_time_h(
    h_base: float, seconds_base: float, seconds: float, h_run: float | None = None
) -> float | None:
    """The finest step at which a setting that took ``seconds`` at h_run (default h_base)
    takes at most EQUAL_TIME_BUDGET of the baseline's ``seconds_base`` over the same
    simulated span (run time ∝ 1/h): h ≥ h_run · seconds / (EQUAL_TIME_BUDGET ·
    seconds_base), on the grid GRID/N so every sample time stays a step boundary.  None
    when that is not finer than h_base (the setting is not fast enough)."""
    if not (seconds > 0.0 and seconds_base > 0.0):
        return None
    coarsest = (h_run or h_base) * seconds / (EQUAL_TIME_BUDGET * seconds_base)
    n = math.floor(GRID / coarsest + 1e-9)
    h = GRID / n if n >= 1 else math.inf
    return h if h < h_base * (1.0 - 1e-9) else None


def equal_time_rows(
    rows: list[PrecisionRow],
    settings: list[Setting],
    repeats: int | None,
    reference_h: dict[str, float],
) -> list[PrecisionRow]:
    """Measured points at equal run time, so the verdict's "lower error at equal or lower
    run time" compares runs, never an interpolated curve: each EQUAL_TIME setting that
    was fast enough at one of the baseline's steps runs again at the finest step planned
    to spend at most EQUAL_TIME_BUDGET of the baseline's time there (``equal_time_h``;
    judged on each scene's longest row, its whole run).

    Each such run is timed beside the baseline at that step, their runs interleaved
    (``_timed``): the baseline row was measured minutes earlier, and the shared machine's
    speed drifts by up to ~1.5× in that time (one study's equal-time doll runs came out
    at 0.69× the speed of the same setting's runs before them).  The run's seconds are
    reported in the baseline row's terms, × its seconds ÷ the baseline's re-timed ones,
    so they compare with that row (and only that one: ``beside``).  Their note is
    EQUAL_TIME_NOTE.  A run that took longer than the baseline's row (the plan rests on
    the first timings, whose ratios carry the machine's noise) is planned once more from
    its own time beside the baseline and run again at that coarser step (REPLANNED_NOTE);
    both runs are rows, and the step is chosen by time alone, never by error."""
    by_name = {s.name: s for s in (*SETTINGS, *settings)}
    longest: dict[tuple, PrecisionRow] = {}
    for r in rows:
        key = (ROW_KIND.get(r.scene), r.setting, r.h)
        if math.isfinite(r.seconds) and (key not in longest or r.steps > longest[key].steps):
            longest[key] = r
    out = []
    for (kind, name, h), r in longest.items():
        base = longest.get((kind, BASELINE, h))
        if name in EQUAL_TIME and name in by_name and base is not None:
            baseline = (by_name[BASELINE], base)
            h_eq = equal_time_h(h, base.seconds, r.seconds)
            got = [] if h_eq is None else _beside(kind, by_name[name], h_eq, baseline, repeats,
                                                  reference_h)  # fmt: skip
            out += got
            if got and got[-1].seconds > base.seconds:  # over the baseline's time: re-planned
                h_eq = equal_time_h(h, base.seconds, got[-1].seconds, h_eq)
                if h_eq is not None:
                    again = _beside(kind, by_name[name], h_eq, baseline, repeats, reference_h)
                    out += [x if x.note != EQUAL_TIME_NOTE else replace(x, note=REPLANNED_NOTE)
                            for x in again]  # fmt: skip
    return out


def _beside(kind, setting, h, baseline, repeats, reference_h) -> list[PrecisionRow]:
    """The rows of ``setting`` at h timed beside baseline = (its Setting, its longest row
    at its own h), in that row's terms (``equal_time_rows``)."""
    base_setting, base_row = baseline
    sc, _ = _scene(kind, setting, h)
    sc_base, _ = _scene(kind, base_setting, base_row.h)
    timed, base_timed = _timed([sc, sc_base], repeats)
    if isinstance(base_timed, SimulationError):  # (it ran before: never seen)
        timed = base_timed
    elif not isinstance(timed, SimulationError):
        got, walls, substeps = timed
        timed = (got, walls * (base_row.seconds / float(base_timed[1][-1])), substeps)
    return _measured_rows(kind, sc, setting, h, timed, reference_h, EQUAL_TIME_NOTE, base_row.h)


def format_table(rows: list[PrecisionRow]) -> str:
    """A fixed-width table of the rows (nan shown as -), then each reference's error."""
    head = (
        f"{'scene':<8} {'setting':<19} {'h (s)':>6} {'steps':>6} {'seconds':>8} "
        f"{'steps/s':>8} {'× real':>7} {'error':>9} unit {'× base t':>8} {'subst':>5}  note"
    )
    lines = [head, "-" * len(head)]
    for r in rows:
        lines.append(
            f"{r.scene:<8} {r.setting:<19} {r.h:>6g} {r.steps:>6} {_num(r.seconds, 8, '.4f')} "
            f"{_num(r.steps_per_s, 8, ',.0f')} {_num(r.realtime, 7, '.1f')} "
            f"{_num(r.error, 9, '.2e')} {r.unit:<4} {_num(r.time_ratio, 8, '.2f')} "
            f"{_num(r.substeps, 5, '.2f')}  {r.note}"
        )
    lines += _reference_lines(rows)
    return "\n".join(lines)


def _reference_lines(rows: list[PrecisionRow]) -> list[str]:
    """Each reference's own error: ours per scene, MuJoCo's per scene and integrator."""
    refs = {}
    for r in rows:
        whose = f"MuJoCo's ({r.setting})" if r.setting.startswith("mujoco") else "our"
        if r.ref_error:
            refs.setdefault((r.scene, whose), (r.ref_error, r.unit))
    return [f"{scene}: {whose} reference's own error ≈ {err:.1e} {unit}"
            for (scene, whose), (err, unit) in refs.items()]  # fmt: skip


def _num(x: float, width: int, spec: str) -> str:
    return f"{'-':>{width}}" if not math.isfinite(x) else f"{x:>{width}{spec}}"


def csv_text(rows: list[PrecisionRow]) -> str:
    """Every row and every field as CSV (nan as ``nan``)."""
    fields = list(PrecisionRow.__dataclass_fields__)
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(fields)
    writer.writerows([getattr(r, f) for f in fields] for r in rows)
    return out.getvalue()


def write_outputs(rows: list[PrecisionRow], out_dir: Path) -> tuple[Path, Path]:
    """precision.csv and precision.png in out_dir (replaced if present), each atomically."""
    from puppetcli.bench.precision_plot import plot_png

    out_dir.mkdir(parents=True, exist_ok=True)
    csv_path, png_path = out_dir / "precision.csv", out_dir / "precision.png"
    write_text_atomic(csv_path, csv_text(rows))
    with atomic_path(png_path) as tmp:
        tmp.write_bytes(plot_png(rows))
    return csv_path, png_path
