"""``puppetcli bench``: steps per second of each solver on the doll, as ratios to PGS."""

from __future__ import annotations

from pathlib import Path

import click

from puppetcli.bench import csv_text, doll_scenes, format_table, measure
from puppetcli.outputs import write_text_atomic

SOLVERS = ["pgs", "auto", "direct", "reference"]


@click.command("bench")
@click.option(
    "--h",
    "steps_h",
    type=float,
    multiple=True,
    default=(0.001, 0.02),
    show_default=True,
    help="Step sizes to measure (repeatable).",
)
@click.option(
    "--solver",
    "solvers",
    type=click.Choice(SOLVERS),
    multiple=True,
    default=tuple(SOLVERS),
    show_default=True,
    help="Solvers to measure (repeatable).",
)
@click.option(
    "--seconds",
    type=click.FloatRange(min=0.0, min_open=True),
    default=0.5,
    show_default=True,
    help="Simulated time per configuration (the reference solver runs 20 steps).",
)
@click.option(
    "--csv",
    "csv_path",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Also write the table as CSV.",
)
@click.option(
    "--precision",
    is_flag=True,
    help="Run the work-precision study instead (error against run time; ignores --h, "
    "--solver, --seconds, --csv).",
)
@click.option("--quick", is_flag=True, help="With --precision: fewer settings and steps (CI).")
@click.option(
    "--out",
    "out_dir",
    type=click.Path(file_okay=False, path_type=Path),
    help="With --precision: write precision.csv and precision.png into this directory "
    "(created if missing; those two files are replaced).",
)
def command(
    steps_h: tuple[float, ...],
    solvers: tuple[str, ...],
    seconds: float,
    csv_path: Path | None,
    precision: bool,
    quick: bool,
    out_dir: Path | None,
) -> None:
    """Measure steps per second of the solvers on example scenes.

    Scenes: `doll` (rigs/doll.yaml: ground contacts, limits, rheology, a grip lifting
    the left forearm along a minimum-jerk path) and `doll-joints` (the same doll
    without ground or limits: two-sided rows only, where the direct solver applies).  The ratio
    column is against PGS (15 iterations, warm start) on the numpy step at the same
    scene and step, measured in the same run; every solver runs on both engines
    (numpy: the reference implementation; fast: the compiled step the CLI uses).

    With --precision: the work-precision study (puppetcli/precision.py): the creep
    experiment against its exact solution and a 10-link chain against a converged
    reference, for PGS (5/15/50 iterations, warm start off/on/0.7), direct and auto at
    h = 1, 5, 20 ms on the compiled step.
    """
    if precision:
        _precision(quick, out_dir)
        return
    rows = measure(doll_scenes(), list(steps_h), list(solvers), seconds)
    click.echo(format_table(rows))
    if csv_path is not None:
        write_text_atomic(csv_path, csv_text(rows))


def _precision(quick: bool, out_dir: Path | None) -> None:
    from puppetcli.precision import format_table as precision_table
    from puppetcli.precision import study, write_outputs

    rows = study(quick=quick)
    click.echo(precision_table(rows))
    if out_dir is not None:
        for path in write_outputs(rows, out_dir):
            click.echo(f"wrote {path}")
