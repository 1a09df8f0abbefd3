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
def command(
    steps_h: tuple[float, ...], solvers: tuple[str, ...], seconds: float, csv_path: Path | None
) -> None:
    """Measure steps per second of the solvers on example scenes.

    Scenes: `doll` (rigs/doll.yaml: ground contacts, limits, rheology, a grip lifting
    the left forearm along a minimum-jerk path) and `doll-joints` (the same doll
    without ground or limits: two-sided rows only, where the direct solver applies).  The ratio
    column is against PGS (15 iterations, warm start) on the numpy step at the same
    scene and step, measured in the same run; every solver runs on both engines
    (numpy: the reference implementation; fast: the compiled step the CLI uses).
    """
    rows = measure(doll_scenes(), list(steps_h), list(solvers), seconds)
    click.echo(format_table(rows))
    if csv_path is not None:
        write_text_atomic(csv_path, csv_text(rows))
