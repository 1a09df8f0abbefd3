"""``puppetcli bench``: steps/s of the solvers on the doll, or the work-precision study."""

from __future__ import annotations

from pathlib import Path

import click

from puppetcli.bench.solvers import (
    INSTALL_HINT,
    SOLVERS,
    csv_text,
    doll_scenes,
    doll_stages,
    format_table,
    measure,
    peer_summary,
    stage_table,
)
from puppetcli.commands.options import STEP, Number
from puppetcli.commands.report import JSON_OPTION, emit, rows_json
from puppetcli.outputs import write_text_atomic

SOLVER_CHOICES = [*SOLVERS, "reference"]


@click.command("bench")
@click.option(
    "--h",
    "steps_h",
    type=STEP,
    multiple=True,
    default=(0.001, 0.02),
    show_default=True,
    help="Step sizes to measure (repeatable).",
)
@click.option(
    "--solver",
    "solvers",
    type=click.Choice(SOLVER_CHOICES),
    multiple=True,
    default=SOLVERS,
    show_default=True,
    help="Solvers to measure (repeatable; reference runs on the numpy step only).",
)
@click.option(
    "--engine",
    "engines",
    type=click.Choice(["fast", "sim", "numpy"]),
    multiple=True,
    default=("fast", "sim"),
    show_default=True,
    help="Steps to run every solver on (repeatable): fast_step (a new State a step, as the "
    "CLI), sim (the same kernel stepping in place, as for a device) or numpy; numpy PGS, "
    "the baseline, always runs.",
)
@click.option(
    "--seconds",
    type=Number(1e-3, 3600.0),
    default=0.5,
    show_default=True,
    help="Simulated time of the lift per run (runs repeat until enough steps are timed; "
    "the reference solver runs 20 steps).",
)
@click.option(
    "--csv",
    "csv_path",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Also write the table as CSV.",
)
@click.option(
    "--peers",
    is_flag=True,
    help="Also measure MuJoCo on the same rig and scene in the same run (needs the "
    "optional mujoco package: pip install -e '.[bench]').",
)
@click.option(
    "--precision",
    is_flag=True,
    help="Run the work-precision study instead (error against run time; ignores --h, "
    "--solver, --engine, --seconds, --csv).",
)
@click.option(
    "--accuracy",
    is_flag=True,
    help="Measure error against run time on like-for-like scenes instead: ours (bdf2 and "
    "the paper's euler) and MuJoCo (Euler, implicitfast, RK4; needs the bench extra) "
    "against a DOP853 truth, an equal-time table, and our large steps (20–250 ms).",
)
@click.option(
    "--skips",
    is_flag=True,
    help="Measure each skip of unneeded work on and off instead (puppetcli/bench/skips.py).",
)
@click.option(
    "--pins",
    is_flag=True,
    help="Measure the cost of 0, 1 and 4 pins on the doll's grip scene instead "
    "(puppetcli/bench/pins.py).",
)
@click.option(
    "--live",
    is_flag=True,
    help="Measure `puppetcli live`'s loop instead: real-time factor, headroom and "
    "input-to-frame latency with a scripted page (--h defaults to 1 and 5 ms here).",
)
@click.option(
    "--pose",
    is_flag=True,
    help="Measure a scripted pose (rigs/doll.yaml scripts/wave.yaml, as `pose` runs it, "
    "with and without its trace) against the bare in-place stepper on the same inputs "
    "instead (--h: steps to run it at; default the script's own and 1 ms).",
)
@click.option(
    "--batch",
    is_flag=True,
    help="Measure `puppetcli batch` instead: jobs per minute and steps/s on 1 and 2 local "
    "workers, and its overhead per job against pose run in-process (puppetcli/bench/batch.py).",
)
@click.option("--quick", is_flag=True, help="With --precision: fewer settings and steps (CI).")
@click.option(
    "--out",
    "out_dir",
    type=click.Path(file_okay=False, path_type=Path),
    help="With --precision or --accuracy: write precision.csv and precision.png (or "
    "accuracy.csv) into this directory "
    "(created if missing; those two files are replaced).",
)
@JSON_OPTION
def command(
    steps_h: tuple[float, ...],
    solvers: tuple[str, ...],
    engines: tuple[str, ...],
    seconds: float,
    csv_path: Path | None,
    peers: bool,
    precision: bool,
    accuracy: bool,
    skips: bool,
    pins: bool,
    live: bool,
    pose: bool,
    batch: bool,
    quick: bool,
    out_dir: Path | None,
    as_json: bool,
) -> None:
    """Measure steps per second of the solvers on the doll.

    Scenes: `doll` (rigs/doll.yaml: ground contacts, limits, rheology, a grip lifting
    the left forearm along a minimum-jerk path) and `doll-joints` (the same doll
    without ground or limits: two-sided rows only, where the direct solver applies).
    Every solver runs on the compiled step, as `fast` (a new State every step, what the
    CLI's script runner does) and `sim` (the same kernel stepping its own arrays in
    place, the loop for driving a device, as MuJoCo's mj_step); the ratio column is
    against PGS (15 iterations, warm start) on the numpy step at the same scene and
    step, measured in the same run.  With --peers, MuJoCo (Euler and implicitfast) on
    the same doll scene, and the ratio of ours to it.  The runs of all configurations
    are interleaved round by round, so a drifting machine slows them alike.

    After the table, where a doll step's time goes, stage by stage (read from the
    processor's cycle counter inside the compiled step).  With --skips: each skip of
    unneeded work (pair culling, dormant rows, leaf contacts, the direct solve, sleeping)
    on and off.  With --pins: the grip scene with 0, 1 and 4 pins.

    With --accuracy: error against run time on like-for-like scenes (puppetcli/bench/
    likeforlike.py: Voigt chains and the doll, released or pulled, no contacts) for our two
    integrators and MuJoCo's Euler, implicitfast and RK4, against a DOP853 truth of the
    same equations; each engine's time to reach 3, 1, 0.3 and 0.1 mm; our large steps.

    With --precision: the work-precision study (puppetcli/bench/precision.py): creep against
    its exact solution, a 10-link chain after 1 s and 3 s and the gripped doll against
    converged references, for PGS (5/15/50 sweeps, warm start off/on/0.7), direct, auto
    and hybrid (15/50 sweeps) at h = 1, 5, 20 ms on the compiled step, with a verdict
    per scene against the paper's setting (PGS 15, warm start) at equal run time.
    """
    if live:
        from puppetcli.bench.live import format_live, measure_live

        source = click.get_current_context().get_parameter_source("steps_h")
        default = source == click.core.ParameterSource.DEFAULT
        rows = measure_live([0.001, 0.005] if default else list(steps_h))
        emit({"live": rows_json(rows)}, [format_live(rows)])
        return
    if pose:
        from puppetcli.bench.pose import format_pose, measure_pose

        source = click.get_current_context().get_parameter_source("steps_h")
        default = source == click.core.ParameterSource.DEFAULT
        rows = measure_pose([None, 0.001] if default else list(steps_h))
        emit({"pose": rows_json(rows)}, [format_pose(rows)])
        return
    if batch:
        from puppetcli.bench.batch import format_batch, measure_batch

        rows, figures = measure_batch()
        emit({"batch": rows_json(rows), **figures}, [format_batch(rows, figures)])
        return
    if pins:
        from puppetcli.bench.pins import format_pins, measure_pins

        rows = measure_pins(steps_h[0], seconds)
        emit({"pins": rows_json(rows)}, [format_pins(rows, steps_h[0])])
        return
    if skips:
        from puppetcli.bench.skips import format_skips, measure_skips

        rows = measure_skips(steps_h[0], seconds)
        emit({"skips": rows_json(rows)}, [format_skips(rows, steps_h[0])])
        return
    if accuracy:
        _accuracy(out_dir, _peers_available())
        return
    use_peers = peers and _peers_available()
    if precision:
        _precision(quick, out_dir, use_peers)
        return
    rows = measure(doll_scenes(), list(steps_h), list(solvers), seconds, engines, use_peers)
    stages = doll_stages(steps_h[0], seconds)
    if csv_path is not None:
        write_text_atomic(csv_path, csv_text(rows))
    lines = [format_table(rows), *peer_summary(rows)]
    lines.append(
        f"\nwhere the time goes: doll, auto, h = {steps_h[0]:g} s (compiled step, per stage)"
    )
    lines.append(stage_table(stages))
    emit({"rows": rows_json(rows), "peers": peer_summary(rows), "stages": stages}, lines)


def _peers_available() -> bool:
    """True when MuJoCo can be used; otherwise says how to get it (the run goes on)."""
    from puppetcli.bench import peers

    version = peers.mujoco_version()
    click.echo(INSTALL_HINT if version is None else f"peers: MuJoCo {version}", err=True)
    return version is not None


def _accuracy(out_dir: Path | None, peers: bool) -> None:
    from puppetcli.bench import likeforlike as lfl

    runs = lfl.study(peers=peers)
    large = lfl.large_steps()
    rows = lfl.equal_time(runs)
    written = []
    if out_dir is not None:
        out_dir.mkdir(parents=True, exist_ok=True)
        path = out_dir / "accuracy.csv"
        write_text_atomic(path, lfl.csv_text(runs + large))
        written.append(path)
    lines = [lfl.format_runs(runs), "", lfl.format_equal_time(rows), "",
             "large steps (RMS error at t = 1 and 2 s):", lfl.format_runs(large),
             *(f"wrote {p}" for p in written)]  # fmt: skip
    emit({"runs": rows_json(runs), "equal_time": rows_json(rows), "large": rows_json(large)},
         lines)  # fmt: skip


def _precision(quick: bool, out_dir: Path | None, peers: bool) -> None:
    from puppetcli.bench.precision import format_table as precision_table
    from puppetcli.bench.precision import study, write_outputs
    from puppetcli.bench.precision_peers import stability_lines
    from puppetcli.bench.verdict import verdicts

    rows = study(quick=quick, peers=peers)
    notes = verdicts(rows) + stability_lines(peers)
    written = write_outputs(rows, out_dir) if out_dir is not None else ()
    lines = [precision_table(rows), *notes, *(f"wrote {path}" for path in written)]
    emit({"precision": rows_json(rows), "verdicts": notes, "outputs": [str(p) for p in written]},
         lines)  # fmt: skip
