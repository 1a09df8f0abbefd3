"""``puppetcli feel RIG``: how each joint of a rig feels, measured by simulation."""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import click

from puppetcli.commands.options import ENGINE_OPTION, Number, force_option, joint_indices
from puppetcli.commands.report import JSON_OPTION, emit, progress_bar
from puppetcli.feel.measure import measure_joint, rest_run
from puppetcli.feel.operator import Hand, run_task
from puppetcli.feel.plot import joint_png, overview_png, task_png, write_plots
from puppetcli.feel.report import feel_csv, feel_json, feel_table
from puppetcli.feel.taskreport import TaskRun, task_csv, task_json, task_table
from puppetcli.feel.tasks import read_task
from puppetcli.outputs import make_parent, refuse_overwrite, write_text_atomic
from puppetcli.rig.load import load_rig
from puppetcli.run.warmup import prepare_engine
from puppetcli.spidar import preset_from_option
from puppetcli.spidar.tensions import least_capacity
from solver.model import build_model


@click.command("feel")
@click.argument("rig", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option(
    "--joint", "joints", multiple=True,
    help="Measure this joint (a bone's name; repeat for more) [default: every joint].",
)  # fmt: skip
@click.option(
    "--angle", type=Number(1.0, 90.0), default=30.0, show_default=True,
    help="The bend, degrees.",
)  # fmt: skip
@click.option(
    "--time", "duration", type=Number(0.05, 10.0), default=1.0, show_default=True,
    help="Seconds the bend takes.",
)  # fmt: skip
@click.option("--csv", "csv_path", type=click.Path(dir_okay=False, path_type=Path),
              help="Write the measures as CSV, one row per joint and axis.")  # fmt: skip
@click.option("--plot", "plot_dir", type=click.Path(file_okay=False, path_type=Path),
              help="Write angle-against-time plots: DIR/JOINT.png, DIR/overview.png.")  # fmt: skip
@click.option(
    "--task", "tasks", multiple=True, type=click.Path(exists=True, dir_okay=False, path_type=Path),
    help="Instead: pose the doll to this keyframes.json's keys with the built-in operator "
    "and report how it went (repeat for more; scripts/tasks/ has three).",
)  # fmt: skip
@click.option(
    "--dof", "dofs", multiple=True, type=click.Choice(["3", "6"]),
    help="With --task: the device's degrees of freedom, 3 (position only) or 6 "
    "[default: both, side by side].",
)  # fmt: skip
@click.option(
    "--device",
    help="With --task: a SPIDAR-G preset (name or YAML); reports the share of the time the "
    "hand pushes harder than it can display.",
)  # fmt: skip
@click.option(
    "--compare", type=click.Path(exists=True, dir_okay=False, path_type=Path),
    help="With --task: a second rig (other coefficients, the same bones), side by side.",
)  # fmt: skip
@force_option("existing CSV and plot files")
@ENGINE_OPTION
@JSON_OPTION
def command(
    rig: Path,
    joints: tuple[str, ...],
    angle: float,
    duration: float,
    csv_path: Path | None,
    plot_dir: Path | None,
    tasks: tuple[Path, ...],
    dofs: tuple[str, ...],
    device: str | None,
    compare: Path | None,
    force: bool,
    engine: str,
    as_json: bool,
) -> None:
    """Measure how the joints of RIG feel, by simulating the rig as it is (gravity,
    neighbours, limits and all): per joint, on a swing axis and the twist axis,

    \b
    - effort: the grip torque (and force at the bone's tip) to bend it by --angle
      in --time, and the joint's own torque;
    - retention: the share of the bend kept 2 s after letting go;
    - spring-back: the angle given back and its time constant;
    - creep: drift per second under a constant torque below the yield torque;
    - hold: drift over 10 s after the bend, and from rest under gravity;
    - flow onset: the torque at which the joint starts to flow.

    Each is printed beside what the joint alone would do (the three-element model's
    closed form), so the neighbours' share shows.

    With --task, a built-in operator poses the doll instead, from rest to each key of
    the task, at 3 and 6 DOF (and on a --compare rig): time to within 2°, grips, the
    hand's path and peak force, the error per joint and how much of the pose survives
    letting go.  See docs/feel.md.
    """
    if tasks:
        _refuse(force, csv_path, *(plot_dir / f"{t.stem}.png" for t in tasks if plot_dir))
        run_tasks(rig, compare, tasks, dofs, device, engine, (csv_path, plot_dir))
        return
    for name, value in (("--dof", dofs), ("--device", device), ("--compare", compare)):
        if value:
            raise click.UsageError(f"{name} goes with --task")
    spec = load_rig(rig)
    model = build_model(spec)
    wanted = joint_indices(model.joint_names, joints)
    _refuse(force, csv_path, plot_dir / "overview.png" if plot_dir else None)
    model, _ = prepare_engine(model, engine, rig)
    hold = rest_run(model)
    found = []
    with progress_bar("measuring", len(wanted)) as tick:
        for j in wanted:
            found.append(measure_joint(model, j, math.radians(angle), duration, hold))
            if tick:
                tick(1)
    written = _write(
        csv_path, lambda: feel_csv(found), plot_dir,
        lambda: {j.joint: joint_png(j) for j in found} | {"overview": overview_png(found)},
    )  # fmt: skip
    facts = {"rig": str(rig), "angle": angle, "time": duration, "joints": feel_json(found),
             "written": written}  # fmt: skip
    lines = [feel_table(found)] + [f"wrote {w}" for w in written]
    emit(facts, lines)


def run_tasks(
    rig: Path, compare: Path | None, tasks: tuple[Path, ...], dofs: tuple[str, ...],
    device: str | None, engine: str, out: tuple[Path | None, Path | None],
) -> None:  # fmt: skip
    """``feel --task``: every task on every rig at every DOF; the table, CSV, JSON."""
    rigs = [rig] + ([compare] if compare is not None else [])
    models = [build_model(load_rig(r)) for r in rigs]
    names = [m.joint_names for m in models]
    if any(n != names[0] for n in names):
        raise click.UsageError(f"--compare: expected a rig with the joints of {rig}")
    cap = least_capacity(preset_from_option(device)) if device else (math.inf, math.inf)
    chosen = sorted({int(d) for d in dofs} or {3, 6}, reverse=True)
    engines = [prepare_engine(m, engine, r) for m, r in zip(models, rigs, strict=True)]
    work = [(t, read_task(t, models[0])) for t in tasks]
    runs = []
    label = (lambda r: r.stem) if compare is None or compare.stem != rig.stem else str
    with progress_bar("posing", len(work) * len(rigs) * len(chosen)) as tick:
        for task, keys in work:
            for (model, upgrade), path in zip(engines, rigs, strict=True):
                for dof in chosen:
                    if upgrade is not None and upgrade():  # built meanwhile: go on compiled
                        model = model.with_options(engine="compiled")
                    found = run_task(model, keys, Hand(dof=dof, capacity=cap))
                    runs.append(TaskRun(f"{label(path)} {dof}-DOF", task.stem, names[0], found))
                    if tick:
                        tick(1)
    csv_path, plot_dir = out
    written = _write(
        csv_path, lambda: task_csv(runs), plot_dir,
        lambda: {t.stem: task_png(t.stem, [r for r in runs if r.task == t.stem]) for t, _ in work},
    )  # fmt: skip
    facts = {"rigs": [str(r) for r in rigs], "device": device,
             "capacity": [None if math.isinf(c) else c for c in cap],
             "tasks": task_json(runs), "written": written}  # fmt: skip
    lines = [task_table(runs)]
    if device:
        lines.append(f"{device} displays at most {cap[0]:.1f} N and {cap[1]:.2f} N·m "
                     "in every direction")  # fmt: skip
    emit(facts, lines + [f"wrote {w}" for w in written])


def _refuse(force: bool, *paths: Path | None) -> None:
    """Stop before any work if an output exists (unless --force)."""
    for path in paths:
        if path is not None:
            refuse_overwrite(path, force)


def _write(
    csv_path: Path | None, csv_text: Callable[[], str], plot_dir: Path | None,
    pictures: Callable[[], dict],
) -> list[str]:  # fmt: skip
    """The CSV (when asked) and the plots (when asked), made only then: the paths written."""
    written = []
    if csv_path is not None:
        make_parent(csv_path)
        write_text_atomic(csv_path, csv_text())
        written.append(str(csv_path))
    if plot_dir is not None:
        written += write_plots(plot_dir, pictures())
    return written
