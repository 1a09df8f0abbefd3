"""``puppetcli pose RIG SCRIPT -o OUTDIR``: run a manipulation script (or replay a recorded
session, ``.mcap``), write keys and a trace."""

from __future__ import annotations

from pathlib import Path

import click

from puppetcli.commands.options import (
    ENGINE_OPTION,
    RATE,
    YES_OPTION,
    force_option,
    order_option,
    scale_option,
    step_option,
    view_option,
)
from puppetcli.commands.report import JSON_OPTION, emit, progress_bar
from puppetcli.errors import ScriptError
from puppetcli.outputs import prepare_outdir
from puppetcli.render.camera import View
from puppetcli.rig.load import load_rig
from puppetcli.run.budget import BudgetWatch, check_run
from puppetcli.run.pose import PoseOptions, plan_pose, run_pose, write_pose
from puppetcli.run.runner import RunResult
from puppetcli.run.warmup import prepare_engine


@click.command("pose")
@click.argument("rig", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.argument("script", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option(
    "-o",
    "--out",
    "outdir",
    type=click.Path(file_okay=False, path_type=Path),
    default=Path("out"),
    show_default=True,
    help="Output directory (created if missing).",
)
@force_option("existing outputs in OUTDIR")
@click.option(
    "--trace-every",
    type=click.IntRange(min=1),
    default=1,
    show_default=True,
    help="Write the trace every N steps.",
)
@click.option("--no-trace", is_flag=True, help="Do not write trace.mcap.")
@step_option("the rig's and the script's or session's")
@click.option("--no-render", is_flag=True, help="Do not draw keys/NNN.png and sheet.png.")
@order_option("keyframes.bvh")
@click.option(
    "--fps",
    type=RATE,
    default=30.0,
    show_default=True,
    help="Frame Time of keyframes.bvh is 1/fps (one frame per key).",
)
@click.option(
    "--interpolate",
    type=click.Choice(["none", "slerp"]),
    default="none",
    show_default=True,
    help="keyframes.bvh: 'slerp' samples a timed motion at --fps between the keys.",
)
@scale_option("keyframes.bvh: length unit factor (100 = centimetres).")
@click.option(
    "--gltf",
    is_flag=True,
    help="Also write keyframes.glb (glTF 2.0: the doll, skinned, with the keys as an animation).",
)
@view_option("the pictures")
@ENGINE_OPTION
@YES_OPTION
@JSON_OPTION
def command(
    rig: Path,
    script: Path,
    outdir: Path,
    force: bool,
    trace_every: int,
    no_trace: bool,
    step: float | None,
    no_render: bool,
    order: str,
    fps: float,
    interpolate: str,
    scale: float,
    gltf: bool,
    view: View,
    engine: str,
    yes: bool,
    as_json: bool,
) -> None:
    """Run a manipulation script (or replay a session .mcap) on a rig: keyframes, BVH, a
    trace and pictures.

    Writes OUTDIR/keyframes.json, OUTDIR/keyframes.bvh (one frame per key), with
    --gltf OUTDIR/keyframes.glb,
    OUTDIR/trace.mcap, OUTDIR/keys/NNN.png (one picture per key) and
    OUTDIR/sheet.png (all keys, one framing); existing files
    are kept unless --force.  If the simulation fails, the keys taken and the trace
    steps written before the failure are still saved, and the exit status is 1.
    Failed `expect` lines are printed and also end with exit status 1.
    """
    spec = load_rig(rig)
    planned = plan_pose(spec, script, step)
    if planned.replay is not None and planned.replay.warning:
        click.echo(f"warning: {planned.replay.warning}", err=True)
    options = PoseOptions(
        trace_every=trace_every, no_trace=no_trace, step=step, no_render=no_render,
        order=order, fps=fps, scale=scale,
        interpolate=None if interpolate == "none" else interpolate, gltf=gltf, view=view,
    )  # fmt: skip
    steps = check_run(script, planned.plan, planned.model.options.h, len(spec.bones), yes,
                      trace_every=None if no_trace else trace_every)  # fmt: skip
    prepare_outdir(outdir, options.outputs(), force)
    planned.model, upgrade = prepare_engine(planned.model, engine, rig)
    with progress_bar("simulating", round(steps)) as tick:
        watch = BudgetWatch(script, steps, yes, tick)
        result = run_pose(planned, outdir, options, upgrade, watch)
    written = write_pose(outdir, planned, result, options)
    _report(result, planned.model.options.h, written)
    if result.error is not None:
        raise result.error
    failed = [r for r in result.expectations if not r.passed]
    for r in failed:
        click.echo(f"expectation failed: {r.message}", err=True)
    if failed:
        raise ScriptError(
            f"{script}: {len(failed)} of {len(result.expectations)} expectations failed"
        )


def _report(result: RunResult, h: float, written: list[Path]) -> None:
    rate = result.steps / result.wall_time if result.wall_time > 0 else None
    passed = sum(r.passed for r in result.expectations)
    lines = [
        f"{len(result.keys)} keys, {result.state.time:.3f} s simulated in {result.wall_time:.2f} s "
        f"({result.steps} steps of {h:g} s, {rate or 0:,.0f} steps/s)",
        f"peak force on the doll {result.peak_force:.1f} N, "
        f"peak displayed {result.peak_displayed:.1f} N",
    ]
    if result.expectations:
        lines.append(f"expectations: {passed} of {len(result.expectations)} passed")
    failed = passed < len(result.expectations)
    facts = {
        "ok": result.error is None and not failed,
        "keys": [{"label": k.label, "time": k.time} for k in result.keys],
        "simulated": round(result.state.time, 9),
        "wall_time": result.wall_time,
        "steps": result.steps,
        "h": h,
        "steps_per_second": rate,
        "peak_force": result.peak_force,
        "peak_displayed": result.peak_displayed,
        "expectations": [{"passed": r.passed, "message": r.message} for r in result.expectations],
        "outputs": [str(path) for path in written],
        "error": None if result.error is None else str(result.error),
    }
    emit(facts, lines)
