"""``puppetcli live RIG [-o SESSION.mcap]``: pose the doll by hand in the browser, recorded."""

from __future__ import annotations

import asyncio
import errno
import os
import secrets
import sys
import threading
import time
import webbrowser
from dataclasses import dataclass
from pathlib import Path

import click
import numpy as np

from puppetcli.commands.options import Number, force_option, step_option, view_option
from puppetcli.errors import shown
from puppetcli.live.recording import POINTER_RADIUS, LiveRecording
from puppetcli.live.scene import scene_bounds, scene_description
from puppetcli.live.server import FRAME_HZ, LOOPBACK, LiveServer, Outcome
from puppetcli.mcap.record import FIT_FRACTION, device_reach, fit_workspace
from puppetcli.mcap.session import METADATA_NAME, Workspace
from puppetcli.outputs import prepare_outdir, refuse_overwrite
from puppetcli.render.camera import View
from puppetcli.rig.load import load_rig
from puppetcli.run.outputs import KEY_OUTPUTS, write_key_outputs
from puppetcli.run.warmup import warm_up
from puppetcli.script.actions import GRIP_DEFAULTS
from puppetcli.script.load import DEFAULT_MAX_FORCE, DEFAULT_MAX_TORQUE
from puppetcli.spidar import DevicePreset, preset_from_option
from solver.errors import PuppetError
from solver.model import Model, build_model
from solver.spec import RigSpec

DEFAULT_DEVICE = "SpidarG6X3R"
MARGIN = 0.3  # m of workspace around the rig at rest
REAL_TIME_STEPS = (1e-4, 0.05)  # s: --h outside this is a mistake (or not real time)


@click.command("live")
@click.argument("rig", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option(
    "-o", "--out", "session", type=click.Path(dir_okay=False, path_type=Path), default=None,
    help="The session to record (.mcap); its keys, BVH and pictures go into the folder of "
    "the same name without .mcap.  [default: live-DATE-TIME.mcap]",
)  # fmt: skip
@click.option(
    "--port",
    type=click.IntRange(0, 65535),
    default=8765,
    show_default=True,
    help="Port of the local web server (0: any free port).",
)
@click.option(
    "--host",
    default="127.0.0.1",
    show_default=True,
    help="Address to listen on; anything but loopback lets other machines in.",
)
@click.option("--no-open", is_flag=True, help="Do not open the page in a browser.")
@step_option("the rig's", Number(*REAL_TIME_STEPS))
@click.option(
    "--device",
    default=DEFAULT_DEVICE,
    show_default=True,
    help="The SPIDAR-G preset whose tension programme runs (name or preset YAML).",
)
@view_option("the contact sheet")
@force_option("the session and its outputs")
def command(
    rig: Path, session: Path | None, port: int, host: str, no_open: bool, step: float | None,
    device: str, view: View, force: bool,
) -> None:  # fmt: skip
    """Pose the doll on RIG by hand in the browser, recorded as a session.

    Starts a local web server and opens its page: drag a bone to pull it, Shift+drag
    to grip it whole and turn it, K to take a key, ? for every control.  The physics
    runs here in real time.  Stop with the page's Stop button, Ctrl-C, or by closing
    the page: the session (written as it goes, so a crash loses at most the last
    second) is completed, and keyframes.json, keyframes.bvh, keys/ and sheet.png are
    written next to it.  Replay it with `puppetcli pose RIG SESSION.mcap`.
    """
    session = session or Path(time.strftime("live-%Y%m%d-%H%M%S.mcap"))
    if session.suffix.lower() != ".mcap":
        expected = "a session file name ending in .mcap"
        raise click.BadParameter(
            f"expected {expected}, got {shown(session.name)}", param_hint="'-o'"
        )
    refuse_overwrite(session, force)
    spec = load_rig(rig)
    dev = preset_from_option(device)
    outdir = session.with_suffix("")
    made_outdir = not outdir.exists()
    prepare_outdir(outdir, KEY_OUTPUTS, force)
    model = build_model(spec)
    workspace, radius, start = _fit(model, spec, dev)
    hello = _hello(model, spec, step, dev.name, workspace.offset, radius)
    run = _Run(session, outdir, rig, spec, model, dev, workspace, start, step, view)
    server = LiveServer(hello, secrets.token_urlsafe(18), (workspace.offset, radius), run.finish,
                        host, port)  # fmt: skip
    try:
        outcome = asyncio.run(server.serve(run.begin, lambda url: _ready(url, host, no_open)))
    except OSError as exc:
        if made_outdir and run.live is None:
            outdir.rmdir()  # nothing was recorded: leave no trace
        if exc.errno == errno.EADDRINUSE:
            raise PuppetError(f"{host}:{port} is in use by another program: pick another "
                              "--port (0 = any free port)") from None  # fmt: skip
        raise PuppetError(f"{host}:{port}: cannot listen: {exc.strerror}") from None
    _report(session, outdir, rig, run.live, outcome)
    if outcome.error is not None:
        raise outcome.error


@dataclass
class _Run:
    """One live session's files: ``begin`` opens and starts the recording once the server
    listens, ``finish`` completes it and writes the keys' outputs."""

    session: Path
    outdir: Path
    rig: Path
    spec: RigSpec
    model: Model
    dev: DevicePreset
    workspace: Workspace
    start: np.ndarray
    step: float | None
    view: View
    live: LiveRecording | None = None

    def begin(self) -> LiveRecording:
        f = open(self.session, "wb")  # noqa: SIM115 -- closed by finish(), written as it goes
        recorder = {
            "live": True, "rig": self.model.name, "rig_file": str(self.rig),
            "device": self.dev.name, "started": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        }  # fmt: skip
        self.live = LiveRecording(self.spec, f, self.dev, self.workspace, self.step, self.start,
                                  np.array([1.0, 0, 0, 0]), recorder)  # fmt: skip
        warm_up(self.live.warm_up)
        return self.live

    def finish(self, outcome: Outcome) -> list[str]:
        live = self.live
        live.writer.add_metadata(f"{METADATA_NAME}.end", {
            "reason": outcome.reason, "time": repr(live.time), "keys": str(len(live.runner.keys)),
            "rejected_messages": str(outcome.rejected),
            "error": "" if outcome.error is None else str(outcome.error),
        })  # fmt: skip
        live.close()
        keys = list(live.runner.keys)
        written = write_key_outputs(self.outdir, self.spec, self.model.name, keys, view=self.view,
                                    gltf=True)  # fmt: skip
        return [str(self.session), *(str(p) for p in written)]


def _fit(model: Model, spec: RigSpec, dev: DevicePreset) -> tuple[Workspace, float, np.ndarray]:
    """The workspace that fits the rig at rest plus ``MARGIN`` in 80 % of the device's reach
    (as ``record`` fits a script's path), its ball's radius in the world (m), and where the
    pointer starts."""
    lo, hi = scene_bounds(model, spec)
    box = (lo - MARGIN, hi + MARGIN)
    corners = np.array([[box[i][0], box[j][1], box[k][2]] for i in (0, 1) for j in (0, 1)
                        for k in (0, 1)])  # fmt: skip
    workspace = fit_workspace(corners, dev)
    radius = FIT_FRACTION * device_reach(dev) * workspace.scale
    return workspace, radius, _pointer_start(lo, hi, workspace.offset, radius)


def _hello(model, spec, step, device: str, centre, radius: float) -> dict:
    return {
        "type": "hello", "version": 1, **scene_description(model, spec),
        "h": step or model.options.h, "frame_hz": FRAME_HZ, "device": device,
        "pointer_radius": POINTER_RADIUS, "reach": GRIP_DEFAULTS["reach"],
        "workspace": {"centre": [float(x) for x in centre], "radius": float(radius)},
        "haptics": {"max_force": DEFAULT_MAX_FORCE, "max_torque": DEFAULT_MAX_TORQUE},
    }  # fmt: skip


def _pointer_start(lo, hi, centre, radius: float) -> np.ndarray:
    """In front of the rig's upper part, inside the workspace."""
    start = np.array([0.5 * (lo[0] + hi[0]), lo[1] + 0.75 * (hi[1] - lo[1]), hi[2] + 0.25])
    off = start - centre
    dist = float(np.linalg.norm(off))
    return start if dist <= 0.9 * radius else centre + off * (0.9 * radius / dist)


def _ready(url: str, host: str, no_open: bool) -> None:
    if host not in LOOPBACK:
        click.echo(f"warning: listening on {host}: other machines can reach this page "
                   "(the token in the URL is its only lock)", err=True)  # fmt: skip
    click.echo(f"puppetcli live: {url}")
    click.echo("pose the doll in that page; stop with its Stop button, Ctrl-C or by closing it")
    if not no_open and _has_display():
        threading.Thread(target=webbrowser.open, args=(url,), daemon=True).start()


def _has_display() -> bool:
    return sys.platform in ("darwin", "win32") or bool(
        os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
    )


def _report(session: Path, outdir: Path, rig: Path, live: LiveRecording, outcome: Outcome):
    keys = len(live.runner.keys)
    how = {"stop": "stopped from the page", "signal": "interrupted", "closed": "page closed",
           "error": "simulation failed"}.get(outcome.reason, outcome.reason)  # fmt: skip
    click.echo(f"session {session}: {live.time:.3f} s, {keys} keys ({how}); "
               f"keys, BVH and pictures in {outdir}/")  # fmt: skip
    if outcome.rejected:
        click.echo(f"{outcome.rejected} malformed or excess page messages were rejected")
    click.echo(f"replay: puppetcli pose {rig} {session} -o {outdir}-replay")
