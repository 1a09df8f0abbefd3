"""``puppetcli record RIG SCRIPT -o SESSION.mcap``: the recording a SPIDAR-G would have made."""

from __future__ import annotations

from pathlib import Path

import click

from puppetcli.commands.options import YES_OPTION, Number, force_option
from puppetcli.commands.report import JSON_OPTION, emit
from puppetcli.errors import shown
from puppetcli.mcap.record import record_session
from puppetcli.mcap.session import TICK, write_session
from puppetcli.outputs import make_parent, refuse_overwrite
from puppetcli.rig.load import load_rig
from puppetcli.run.budget import check_run
from puppetcli.run.runner import script_model
from puppetcli.script.load import load_script
from puppetcli.spidar import preset_from_option
from solver.model import build_model

DEFAULT_DEVICE = "SpidarG6X3R"


@click.command("record")
@click.argument("rig", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.argument("script", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option(
    "-o", "--out", required=True, type=click.Path(dir_okay=False, path_type=Path),
    help="The session file to write (.mcap).",
)  # fmt: skip
@click.option(
    "--device", default=DEFAULT_DEVICE, show_default=True,
    help="A built-in preset name (SpidarG6X3R, SpidarG6X3L, SpidarG6X4R, SpidarG6X4L, "
    "HISpidarG6X) or a preset YAML file.",
)  # fmt: skip
@click.option(
    "--noise", type=Number(0.0, 1e6), default=0.0, show_default=True,
    help="Standard deviation of Gaussian noise added to every encoder count (counts).",
)  # fmt: skip
@click.option(
    "--seed",
    type=click.IntRange(0, 2**63 - 1),
    default=0,
    show_default=True,
    help="Seed of the count noise.",
)
@click.option("--with-pose", is_flag=True, help="Also store the true grip pose (/spidar/pose).")
@force_option("SESSION.mcap if it exists")
@YES_OPTION
@JSON_OPTION
def command(
    rig: Path, script: Path, out: Path, device: str, noise: float, seed: int, with_pose: bool,
    force: bool, yes: bool, as_json: bool,
) -> None:  # fmt: skip
    """Turn the manipulation script SCRIPT into the session a SPIDAR-G device would record.

    The pointer path is sampled every 1 ms, mapped into the device (the script's
    `workspace:`, or one fitted so the path fills 80 % of the device's reach) and
    turned into encoder counts; grips, releases and keys become button events,
    pushes and expectations script events.  Replay it with `puppetcli pose RIG
    SESSION.mcap`.  The format is described in docs/sessions.md.
    """
    if out.suffix.lower() != ".mcap":
        expected = "a session file name ending in .mcap"
        raise click.BadParameter(f"expected {expected}, got {shown(out.name)}", param_hint="'-o'")
    refuse_overwrite(out, force)
    spec = load_rig(rig)
    plan = load_script(script, spec)
    model = script_model(build_model(spec), plan)
    check_run(script, plan, model.options.h, len(spec.bones), yes, tick=TICK)
    session = record_session(
        model, plan, preset_from_option(device), noise, seed, store_pose=with_pose
    )
    make_parent(out)
    write_session(out, session)
    ws = session.workspace
    how = "fitted to 80 % of the reach" if ws.fitted else "from the script"
    offset = ", ".join(f"{x:g}" for x in ws.offset)
    line = (
        f"wrote {out}: {len(session.tick_time)} ticks ({session.tick_time[-1]:.3f} s) on "
        f"{session.preset.name}, {len(session.events)} events; workspace offset [{offset}] m, "
        f"scale {ws.scale:g} ({how})"
    )
    facts = {
        "out": str(out), "ticks": len(session.tick_time),
        "duration": round(float(session.tick_time[-1]), 9), "device": session.preset.name,
        "events": len(session.events),
        "workspace": {"offset": ws.offset, "scale": ws.scale, "fitted": ws.fitted},
    }  # fmt: skip
    emit(facts, [line])
