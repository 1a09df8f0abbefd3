"""``puppetcli batch JOBS -o OUTDIR``: many pose runs at once, on this machine's cores or on
a Dask cluster; resumable, with a summary of every job."""

from __future__ import annotations

import contextlib
import glob
import sys
from pathlib import Path

import click
import yaml

from puppetcli.batch.jobs import BatchError, jobs_from_scripts, read_manifest, sweep
from puppetcli.batch.run import LocalPool, dask_pool, run
from puppetcli.commands.options import force_option
from puppetcli.commands.report import JSON_OPTION, emit, progress_bar
from puppetcli.errors import PuppetError
from puppetcli.feel.report import aligned
from puppetcli.rig.load import load_rig
from puppetcli.run.build import compiled_ready
from puppetcli.run.pose import PoseOptions
from puppetcli.run.warmup import warm_up_step
from solver.model import build_model

MANIFESTS = (".csv",)


def _is_manifest(path: Path) -> bool:
    """A CSV file, or a YAML document with a ``jobs`` list (a script has ``actions``)."""
    if path.suffix.lower() in MANIFESTS:
        return True
    if path.suffix.lower() not in (".yaml", ".yml"):
        return False
    try:
        doc = yaml.safe_load(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, yaml.YAMLError):
        return False
    return isinstance(doc, dict) and "jobs" in doc


def _paths(patterns: tuple[str, ...]) -> list[Path]:
    """The files each argument names: itself, or what its glob pattern matches."""
    found: list[Path] = []
    for pattern in patterns:
        matches = sorted(glob.glob(pattern, recursive=True)) if glob.has_magic(pattern) else []
        if glob.has_magic(pattern) and not matches:
            raise BatchError(f"{pattern}: expected scripts, sessions or a manifest, got no match")
        for p in map(Path, matches or [pattern]):
            if not p.is_file():
                raise BatchError(f"{p}: expected a manifest, script or session, got no such file")
            found.append(p)
    return found


def _sweep(text: str) -> tuple[str, list[object]]:
    key, sep, values = text.partition("=")
    if not sep or not key or not values:
        raise click.BadParameter(f"expected KEY=V1,V2,…, got {text!r}", param_hint="'--sweep'")
    return key.strip(), [yaml.safe_load(v) for v in values.split(",")]


def _table(rows: list[dict]) -> str:
    """The summary: a line per job that did not succeed, and the totals."""
    counts: dict[str, int] = {}
    for r in rows:
        counts[r["status"]] = counts.get(r["status"], 0) + 1
    bad = [r for r in rows if r["status"] != "ok"]
    lines = []
    if bad:
        cells = [[r["job"], r["status"], r["error"] or ""] for r in bad]
        lines.append(aligned([["job", "status", "error"], *cells]))
    fresh = [r for r in rows if r.get("fresh")]
    steps = sum(r["steps"] or 0 for r in fresh)
    wall = sum(r["wall_s"] or 0.0 for r in fresh)
    lines.append(", ".join(f"{n} {s}" for s, n in sorted(counts.items()))
                 + f"; {len(fresh)} run now, {len(rows) - len(fresh)} up to date"
                 + (f"; {steps:,} steps at {steps / wall:,.0f} steps/s per worker"
                    if wall > 0 else ""))  # fmt: skip
    return "\n".join(lines)


@click.command("batch")
@click.argument("jobs", nargs=-1, required=True)
@click.option("-o", "--out", "outdir", type=click.Path(file_okay=False, path_type=Path),
              required=True, help="Output folder: OUTDIR/JOB/ per job, OUTDIR/summary.csv "
              "and summary.json.")  # fmt: skip
@click.option(
    "--rig",
    type=click.Path(exists=True, dir_okay=False, path_type=Path),
    help="The rig for scripts and sessions given directly (not in a manifest).",
)
@click.option("--sweep", "sweeps", multiple=True, metavar="KEY=V1,V2,…",
              help="Run every job once per value of a rig value (joints.BONE.kf=50,100); "
              "repeat for a grid.")  # fmt: skip
@click.option(
    "--workers", type=click.IntRange(min=1), help="Local worker processes [default: one per core]."
)
@click.option(
    "--scheduler",
    metavar="ADDRESS",
    help="Run on a Dask cluster (tcp://HOST:PORT) instead of local workers.",
)
@click.option(
    "--retries",
    type=click.IntRange(min=0),
    default=2,
    show_default=True,
    help="Run a job again this many times if its worker dies.",
)
@click.option("--no-render", is_flag=True, help="Default for every job: no pictures.")
@click.option("--no-trace", is_flag=True, help="Default for every job: no trace.mcap.")
@click.option("--gltf", is_flag=True, help="Default for every job: also keyframes.glb.")
@force_option("every job's outputs (run them all again, even when up to date)")
@JSON_OPTION
def command(
    jobs: tuple[str, ...], outdir: Path, rig: Path | None, sweeps: tuple[str, ...],
    workers: int | None, scheduler: str | None, retries: int, no_render: bool,
    no_trace: bool, gltf: bool, force: bool, as_json: bool,
) -> None:  # fmt: skip
    """Run many sessions or scripts at once: what `pose` writes, one folder per job.

    JOBS is a manifest (YAML with a `jobs:` list, or CSV; see docs/batch.md), or
    scripts and sessions (globs too) run on --rig.  A job whose folder holds a finished
    run with the same inputs (rig, overrides, script, options, solver) is not run
    again; a failing job is recorded and the others go on; a job whose worker dies is
    run again (--retries).  OUTDIR/summary.csv and summary.json list every job: status,
    inputs' hashes, keys, failed expectations, simulated and wall time, steps/s, error.
    """
    base = PoseOptions(no_render=no_render, no_trace=no_trace, gltf=gltf)
    found = []
    paths = _paths(jobs)
    scripts = [p for p in paths if not _is_manifest(p)]
    if scripts and rig is None:
        raise click.UsageError(f"{scripts[0]} is a script or session: give the rig with --rig")
    for p in paths:
        found += read_manifest(p, base) if _is_manifest(p) else []
    found += jobs_from_scripts(scripts, rig, base) if scripts else []
    found = sweep(found, [_sweep(s) for s in sweeps])
    pool = dask_pool(scheduler) if scheduler else LocalPool(workers)
    good = [j for j in found if j.error is None]
    if good and not scheduler and not compiled_ready():  # built once here, not per worker
        with contextlib.suppress(PuppetError):  # a bad rig is its job's error, not the batch's
            warm_up_step(build_model(load_rig(good[0].rig)))
    rows: list[dict] = []
    with progress_bar("jobs", len(found)) as tick:
        try:
            rows = run(found, outdir, pool, retries, (lambda r: tick(1)) if tick else None,
                       force=force)  # fmt: skip
        except KeyboardInterrupt:
            click.echo(f"interrupted: finished jobs are complete in {outdir}, "
                       f"see {outdir / 'summary.csv'}", err=True)  # fmt: skip
            sys.exit(130)
    facts = {"outdir": str(outdir), "jobs": rows}
    emit(facts, [_table(rows), f"wrote {outdir / 'summary.csv'}"])
    if any(r["status"] != "ok" for r in rows):
        sys.exit(1)
