"""``puppetcli convert INPUT -o OUT.bvh|OUT.glb --rig RIG``: run a script (or replay a
session), write the motion as BVH or glTF 2.0."""

from __future__ import annotations

from pathlib import Path

import click

from puppetcli.bvh.write import FrameSampler, write_keys_bvh
from puppetcli.commands.options import (
    ENGINE_OPTION,
    RATE,
    YES_OPTION,
    force_option,
    order_option,
    scale_option,
)
from puppetcli.commands.report import JSON_OPTION, emit, progress_bar
from puppetcli.errors import ScriptError, shown
from puppetcli.gltf.export import write_glb
from puppetcli.mcap.replay import load_replay
from puppetcli.outputs import make_parent, refuse_overwrite
from puppetcli.rig.load import load_rig
from puppetcli.rig.skeleton import Skeleton
from puppetcli.run.budget import BudgetWatch, check_run
from puppetcli.run.runner import Runner, script_model
from puppetcli.run.warmup import prepare_engine
from puppetcli.script.load import load_script
from solver.model import build_model

KEYS_FPS = 30.0  # Frame Time of a BVH of keys when no --fps is given


@click.command("convert")
@click.argument("source", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option(
    "-o", "--out", required=True, type=click.Path(dir_okay=False, path_type=Path),
    help="The file to write: .bvh, or .glb (glTF 2.0: the doll, skinned, and the motion).",
)  # fmt: skip
@click.option(
    "--rig", "rig", required=True,
    type=click.Path(exists=True, dir_okay=False, path_type=Path), help="The rig to pose.",
)  # fmt: skip
@click.option(
    "--fps", type=RATE, default=None,
    help="Write the whole motion sampled at this rate [default: one frame per key, at 30 fps].",
)  # fmt: skip
@order_option("every joint")
@scale_option("File units per metre (100 for centimetres).")
@force_option("OUT.bvh if it exists")
@ENGINE_OPTION
@YES_OPTION
@JSON_OPTION
def command(
    source: Path,
    out: Path,
    rig: Path,
    fps: float | None,
    order: str,
    scale: float,
    force: bool,
    engine: str,
    yes: bool,
    as_json: bool,
) -> None:
    """Run the manipulation script SOURCE (.yaml), or replay the recorded session SOURCE
    (.mcap, see docs/sessions.md), on RIG and write its motion as BVH or glTF 2.0
    (by OUT's suffix, .bvh or .glb).

    Without --fps each key of the script is one frame (a .glb holds each key
    until the next); with --fps the whole run is sampled at that rate (a .glb
    interpolates between the samples).  If the simulation fails, the frames before
    the failure are still written and the exit status is 1.
    """
    if out.suffix.lower() not in (".bvh", ".glb"):
        raise click.BadParameter(
            f"expected a .bvh or .glb file name, got {shown(out.name)}", param_hint="'-o'"
        )
    refuse_overwrite(out, force)
    spec = load_rig(rig)
    replay = load_replay(source, spec) if source.suffix.lower() == ".mcap" else None
    if replay is not None and replay.warning:
        click.echo(f"warning: {replay.warning}", err=True)
    plan = replay.script if replay is not None else load_script(source, spec)
    model = script_model(build_model(spec), plan)
    steps = check_run(source, plan, model.options.h, len(spec.bones), yes)
    model, upgrade = prepare_engine(model, engine, rig)
    runner = replay.runner(model) if replay is not None else Runner(model, plan)
    runner.upgrade = upgrade
    sampler = FrameSampler(model, fps, runner.state) if fps is not None else None
    with progress_bar("simulating", round(steps)) as tick:
        runner.on_step, runner.progress = sampler, BudgetWatch(source, steps, yes, tick)
        result = runner.run()
    frames = sampler.frames if sampler is not None else list(result.keys)
    if not frames:
        raise ScriptError(f"{source}: expected at least one 'key' action (or --fps), got none")
    make_parent(out)
    if out.suffix.lower() == ".glb":
        write_glb(out, spec, frames, fps or KEYS_FPS, "LINEAR" if fps else "STEP")
    else:
        write_keys_bvh(out, Skeleton.from_spec(spec), frames, order.upper(), scale, fps or KEYS_FPS)
    what = f"{len(frames)} frames at {fps:g} fps" if fps else f"{len(frames)} keys"
    line = f"wrote {out}: {what}, {result.state.time:.3f} s simulated"
    line += f", order {order.upper()}" if out.suffix.lower() == ".bvh" else ""
    facts = {
        "ok": result.error is None, "out": str(out), "frames": len(frames), "fps": fps or KEYS_FPS,
        "per_key": fps is None, "simulated": round(result.state.time, 9), "order": order.upper(),
        "scale": scale, "error": None if result.error is None else str(result.error),
    }  # fmt: skip
    emit(facts, [line])
    if result.error is not None:
        raise result.error
