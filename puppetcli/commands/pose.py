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
from puppetcli.mcap.replay import Replay, load_replay
from puppetcli.outputs import prepare_outdir
from puppetcli.render.camera import View
from puppetcli.rig.load import load_rig
from puppetcli.run.budget import BudgetWatch, check_run
from puppetcli.run.outputs import write_key_outputs
from puppetcli.run.runner import Runner, RunResult, script_model
from puppetcli.run.trace import RunTrace
from puppetcli.run.warmup import prepare_engine
from puppetcli.script.load import load_script
from solver.model import build_model

OUTPUTS = ["keyframes.json", "keyframes.bvh", "keyframes.glb", "trace.mcap", "sheet.png", "keys"]


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
    replay = load_replay(script, spec) if script.suffix.lower() == ".mcap" else None
    if replay is not None and replay.warning:
        click.echo(f"warning: {replay.warning}", err=True)
    plan = replay.script if replay is not None else load_script(script, spec)
    model = script_model(build_model(spec), plan)
    if step is not None:
        model = model.with_options(h=step)
    steps = check_run(script, plan, model.options.h, len(spec.bones), yes,
                      trace_every=None if no_trace else trace_every)  # fmt: skip
    skipped = {"trace.mcap"} if no_trace else set()
    skipped |= {"sheet.png", "keys"} if no_render else set()
    skipped |= set() if gltf else {"keyframes.glb"}
    prepare_outdir(outdir, [name for name in OUTPUTS if name not in skipped], force)
    model, upgrade = prepare_engine(model, engine, rig)
    with progress_bar("simulating", round(steps)) as tick:
        watch = BudgetWatch(script, steps, yes, tick)
        result = _run(model, plan, outdir, trace_every, no_trace, replay, upgrade, watch)
    written = write_key_outputs(
        outdir, spec, model.name, list(result.keys), render=not no_render, order=order.upper(),
        fps=fps, scale=scale, interpolate=None if interpolate == "none" else interpolate,
        view=view, gltf=gltf,
    )  # fmt: skip
    if not no_trace:
        written.append(outdir / "trace.mcap")
    _report(result, model.options.h, written)
    if result.error is not None:
        raise result.error
    failed = [r for r in result.expectations if not r.passed]
    for r in failed:
        click.echo(f"expectation failed: {r.message}", err=True)
    if failed:
        raise ScriptError(
            f"{script}: {len(failed)} of {len(result.expectations)} expectations failed"
        )


def _run(
    model, plan, outdir: Path, trace_every: int, no_trace: bool, replay: Replay | None, upgrade,
    progress: BudgetWatch,
) -> RunResult:  # fmt: skip
    if replay is not None:
        runner = replay.runner(model, progress=progress)
    else:
        runner = Runner(model, plan, progress=progress)
    runner.upgrade = upgrade
    if no_trace:
        return runner.run()
    path, spidar = outdir / "trace.mcap", replay is not None
    with RunTrace(path, model, plan, trace_every, runner.pointer_on, spidar) as trace:
        runner.trace = trace
        return runner.run()


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
