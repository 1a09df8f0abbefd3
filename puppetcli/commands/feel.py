"""``puppetcli feel RIG``: how each joint of a rig feels, measured by simulation."""

from __future__ import annotations

import math
from pathlib import Path

import click

from puppetcli.commands.options import ENGINE_OPTION, Number, force_option, joint_indices
from puppetcli.commands.report import JSON_OPTION, emit, progress_bar
from puppetcli.feel.measure import measure_joint, rest_run
from puppetcli.feel.plot import joint_png, overview_png, write_plots
from puppetcli.feel.report import feel_csv, feel_json, feel_table
from puppetcli.outputs import make_parent, refuse_overwrite, write_text_atomic
from puppetcli.rig.load import load_rig
from puppetcli.run.warmup import prepare_engine
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
    closed form), so the neighbours' share shows.  See docs/feel.md.
    """
    spec = load_rig(rig)
    model = build_model(spec)
    wanted = joint_indices(model.joint_names, joints)
    for out in (csv_path, plot_dir / "overview.png" if plot_dir else None):
        if out is not None:
            refuse_overwrite(out, force)
    model, _ = prepare_engine(model, engine, rig)
    hold = rest_run(model)
    found = []
    with progress_bar("measuring", len(wanted)) as tick:
        for j in wanted:
            found.append(measure_joint(model, j, math.radians(angle), duration, hold))
            if tick:
                tick(1)
    written = []
    if csv_path is not None:
        make_parent(csv_path)
        write_text_atomic(csv_path, feel_csv(found))
        written.append(str(csv_path))
    if plot_dir is not None:
        pictures = {j.joint: joint_png(j) for j in found} | {"overview": overview_png(found)}
        written += write_plots(plot_dir, pictures)
    facts = {"rig": str(rig), "angle": angle, "time": duration, "joints": feel_json(found),
             "written": written}  # fmt: skip
    lines = [feel_table(found)] + [f"wrote {w}" for w in written]
    emit(facts, lines)
