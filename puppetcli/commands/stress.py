"""``puppetcli stress``: the stress cases of issue 6, one row per case."""

from __future__ import annotations

import csv
import io
from pathlib import Path

import click

from puppetcli.bench.stress import CASES, RANDOM, RANDOM_SEEDS, CaseResult, run_cases
from puppetcli.commands.report import JSON_OPTION, emit, progress_bar, rows_json
from puppetcli.outputs import write_text_atomic
from puppetcli.rig.load import SOLVER_METHODS


@click.command("stress")
@click.option(
    "--case",
    "names",
    type=click.Choice([*CASES, RANDOM]),
    multiple=True,
    help="Run only this case (repeatable).  Default: every case and the random rigs.",
)
@click.option(
    "--seed",
    type=click.IntRange(min=0),
    help=f"Run only the random rig of this seed (default: seeds 0–{RANDOM_SEEDS - 1}).",
)
@click.option(
    "--solver",
    "method",
    type=click.Choice(SOLVER_METHODS),
    help="Solve every case with this solver method (default: each case's own, auto).",
)
@click.option(
    "--csv",
    "csv_path",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Also write the table as CSV (replaced if it exists).",
)
@JSON_OPTION
@click.pass_context
def command(
    ctx: click.Context,
    names: tuple[str, ...],
    seed: int | None,
    method: str | None,
    csv_path: Path | None,
    as_json: bool,
) -> None:
    """Simulate extreme rigs and inputs and check that each stays stable.

    Cases: mass ratio 1:1000, a 100-link chain, h = 50 ms, K_f = 1e6, D_d tiny and
    huge, a 1e5 N/m grip, a grip yanked 1 m in one step, bodies starting deep in
    each other and in the ground, a zero-gravity spin about the intermediate axis,
    and 100 seeded random rigs and pushes (one summary row; --seed N runs one).
    Each row: stable or not, energy growth after the input stops and its bound,
    the worst joint separation, the worst penetration and its bound, whether any
    value went non-finite, steps and wall time (s); docs/stress.md explains the
    bounds.  Exits with status 1 when any case is unstable.
    """
    chosen = list(names) or ([RANDOM] if seed is not None else [*CASES, RANDOM])
    if seed is not None and RANDOM not in chosen:
        raise click.UsageError("--seed selects a random rig: use it with --case random")
    seeds = [seed] if seed is not None else list(range(RANDOM_SEEDS))
    runs = sum(n != RANDOM for n in chosen) + (len(seeds) if RANDOM in chosen else 0)
    with progress_bar("stress", runs) as tick:
        results = run_cases(chosen, seeds, tick and (lambda: tick(1)), method)
    if csv_path is not None:
        write_text_atomic(csv_path, csv_text(results))
    stable = all(r.stable for r in results)
    emit({"ok": stable, "cases": rows_json(results)}, [format_table(results)])
    if not stable:
        ctx.exit(1)


def format_table(results: list[CaseResult]) -> str:
    """A fixed-width table, one row per case."""
    head = (
        f"{'case':<18} {'stable':<6} {'ΔE (J)':>9} {'bound':>9} {'gap (m)':>9} "
        f"{'pen (m)':>9} {'bound':>9} {'NaN':<4} {'steps':>6} {'wall':>6}  problems"
    )
    lines = [head, "-" * len(head)]
    for r in results:
        lines.append(
            f"{r.name:<18} {'yes' if r.stable else 'NO':<6} {r.energy_growth:>9.3g} "
            f"{r.energy_bound:>9.3g} {r.joint_gap:>9.2e} {r.penetration:>9.2e} "
            f"{r.penetration_bound:>9.2e} {'yes' if r.nonfinite else 'no':<4} {r.steps:>6} "
            f"{r.wall:>6.2f}  {'; '.join(r.problems)}"
        )
    return "\n".join(lines)


CSV_FIELDS = (
    "name", "stable", "energy_growth", "energy_bound", "joint_gap", "gap_limit", "penetration",
    "penetration_bound", "momentum_drift", "nonfinite", "steps", "wall", "problems",
)  # fmt: skip


def csv_text(results: list[CaseResult]) -> str:
    """The results as CSV, problems joined by '; '."""
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(CSV_FIELDS)
    for r in results:
        writer.writerow([getattr(r, f) for f in CSV_FIELDS[:-1]] + ["; ".join(r.problems)])
    return out.getvalue()
