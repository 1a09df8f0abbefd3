"""``puppetcli render INPUT -o SHEET.png``: a contact sheet of poses, or a video of a trace."""

from __future__ import annotations

from pathlib import Path

import click

from puppetcli.commands.options import SIZE, YES_OPTION, Number, force_option, view_option
from puppetcli.commands.report import JSON_OPTION, emit, progress_bar
from puppetcli.errors import shown
from puppetcli.mcap.session import is_session
from puppetcli.outputs import make_parent, refuse_overwrite
from puppetcli.render.camera import RenderError, View
from puppetcli.render.inputs import (
    OWN_SKELETON,
    file_rig,
    input_kind,
    key_poses,
    read_own,
    trace_poses,
)  # fmt: skip
from puppetcli.render.picture import (
    contact_sheet,
    default_cols,
    frame_poses,
    render_pose,
    write_png,
)
from puppetcli.render.video import CODECS, frame_count
from puppetcli.rig.load import load_rig
from puppetcli.rig.skeleton import Skeleton
from puppetcli.run.budget import check_budget, video_cost
from puppetcli.run.session_trace import session_trace


@click.command("render")
@click.argument(
    "input_path", metavar="INPUT", type=click.Path(exists=True, dir_okay=False, path_type=Path)
)
@click.option(
    "-o",
    "--out",
    "sheet",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Contact sheet to write (.png): every key in a labelled grid.",
)
@click.option(
    "--rig",
    type=click.Path(exists=True, dir_okay=False, path_type=Path),
    help="Rig file of the poses (bone shapes, props, ground); needed for keyframes.json and "
    "traces [default for a .bvh or .glb: the rig `rig from-bvh`/`from-gltf` makes of it].",
)
@click.option(
    "--frame",
    "frames",
    type=click.IntRange(min=0),
    multiple=True,
    help="With a .bvh or .glb INPUT: draw this frame (0 = the first; repeat for more) "
    "[default: up to 48, evenly spaced].",
)
@click.option(
    "--cols",
    type=click.IntRange(1, 100),
    help="Columns of the sheet [default: up to 4, then ~square].",
)
@view_option("the pictures (front from +z, side from +x, top from +y)")
@click.option(
    "--size", type=SIZE, default="480x480", show_default=True, help="Panel size WIDTHxHEIGHT, px."
)
@click.option(
    "--video",
    type=click.Path(dir_okay=False, path_type=Path),
    help="With a trace or session .mcap INPUT: a video of every step (.mp4 mp4v or .avi MJPG).",
)
@click.option(
    "--fps", type=Number(1.0, 240.0), default=30.0, show_default=True, help="Video frame rate."
)
@force_option("existing output files")
@YES_OPTION
@JSON_OPTION
def command(
    input_path: Path,
    sheet: Path | None,
    rig: Path | None,
    frames: tuple[int, ...],
    cols: int | None,
    view: View,
    size: tuple[int, int],
    video: Path | None,
    fps: float,
    force: bool,
    yes: bool,
    as_json: bool,
) -> None:
    """Draw poses: a contact sheet of keys, or a video of a trace.

    INPUT is keyframes.json, a .bvh or .glb file (its frames, standing on the
    ground), a trace.mcap (sheet: its key moments; --video: every step), a
    recorded session .mcap (replayed first, then drawn as its trace) or a rig
    .yaml (its rest pose).  A .bvh or .glb file needs no --rig: its own
    skeleton is drawn.  All panels share one perspective camera fitted to all poses, so
    they compare directly.  Existing outputs are kept unless --force.
    """
    kind = _check_request(input_path, sheet, video, force, rig, frames)
    say = lambda line: click.echo(line, err=True)  # noqa: E731
    parsed = read_own(input_path, kind)  # a .bvh or .glb: read once for its rig and poses
    spec = load_rig(rig) if rig is not None else file_rig(input_path, kind, say, parsed)
    skel = Skeleton.from_spec(spec)
    if kind == "trace" and is_session(input_path):
        steps, poses = _session_poses(input_path, spec, skel, yes)
    elif kind == "trace":
        steps, poses = trace_poses(input_path, skel)
    else:
        steps, poses = [], key_poses(input_path, kind, skel, spec, frames, say, parsed)
    if video is not None:  # refused before anything is written
        frames = frame_count([p.time for p in steps], fps)
        what = f"{frames:,} video frames at {fps:g} fps"
        check_budget(input_path, what, video_cost(frames, size), yes)
    facts: dict = {"input": str(input_path), "view": view.name, "size": list(size)}
    lines = []
    # The video first: it is the long part, and a failure or Ctrl-C there leaves both outputs
    # as they were.
    if video is not None:
        framing = frame_poses(skel, steps, spec, view, size)
        n = _video(video, skel, steps, spec, framing, fps, frames)
        lines.append(f"{video}: {n} frames at {fps:g} fps ({len(steps)} recorded steps)")
        facts["video"] = {"out": str(video), "frames": n, "fps": fps, "steps": len(steps)}
    if sheet is not None:
        ncols = min(cols if cols is not None else default_cols(len(poses)), len(poses))
        rows = _sheet(sheet, skel, poses, spec, frame_poses(skel, poses, spec, view, size), ncols)
        panels = f"{len(poses)} panel" + ("s" if len(poses) != 1 else "")
        lines.append(f"{sheet}: {panels}, {ncols} × {rows}, "
                     f"{view.name} view, {size[0]}x{size[1]} px each")  # fmt: skip
        facts["sheet"] = {"out": str(sheet), "panels": len(poses), "cols": ncols, "rows": rows}
    emit(facts, lines)


def _sheet(path: Path, skel: Skeleton, poses, spec, framing, ncols: int) -> int:
    """Write the contact sheet of ``poses``; its number of rows."""
    make_parent(path)
    write_png(path, contact_sheet([render_pose(skel, p, spec, framing) for p in poses], ncols))
    return -(-len(poses) // ncols)


def _check_request(
    input_path: Path,
    sheet: Path | None,
    video: Path | None,
    force: bool,
    rig: Path | None,
    frames: tuple[int, ...],
) -> str:
    """Every option checked before any file is read (a mistake is a usage error, status 2);
    returns the input kind."""
    try:
        kind = input_kind(input_path)
    except RenderError as exc:
        raise click.BadParameter(str(exc), param_hint="'INPUT'") from None
    if rig is None and kind not in OWN_SKELETON:
        raise click.UsageError(
            f"missing option '--rig': {shown(input_path.name)} holds poses, not the rig's bones"
        )
    if rig is not None and kind == "rig":
        raise click.UsageError("INPUT is a rig already: leave out --rig")
    if frames and kind not in ("bvh", "gltf"):
        raise click.BadParameter(
            f"expected a .bvh or .glb INPUT, got {shown(input_path.name)}", param_hint="'--frame'"
        )
    if sheet is None and video is None:
        raise click.UsageError("nothing to write: give -o SHEET.png and/or --video OUT.mp4")
    if sheet is not None and sheet.suffix.lower() != ".png":
        raise click.BadParameter(
            f"expected a .png file name, got {shown(sheet.name)}", param_hint="'-o'"
        )
    if video is not None and kind != "trace":
        raise click.BadParameter(
            f"expected a trace or session .mcap INPUT, got {shown(input_path.name)}",
            param_hint="'--video'",
        )
    if video is not None and video.suffix.lower() not in CODECS:
        raise click.BadParameter(
            f"expected an .mp4 or .avi file name, got {shown(video.name)}", param_hint="'--video'"
        )
    for out in (sheet, video):
        if out is not None:
            refuse_overwrite(out, force)
    return kind


def _session_poses(path: Path, spec, skel: Skeleton, yes: bool):
    """(every step, the keys) of a recorded session, replayed into a trace first."""
    return session_trace(path, spec, yes, lambda trace: trace_poses(trace, skel))


def _video(path: Path, skel, steps, spec, framing, fps: float, frames: int) -> int:
    """Write the video of ``steps``; the frames written."""
    from puppetcli.render.video import write_video

    make_parent(path)
    with progress_bar("rendering", frames) as tick:
        return write_video(path, skel, steps, spec, framing, fps, tick and (lambda: tick(1)))
