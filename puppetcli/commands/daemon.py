"""``puppetcli daemon status|stop``: the warm processes that run commands (puppetcli.daemon)."""

from __future__ import annotations

import contextlib
import os
import signal

import click

from puppetcli.daemon.address import SWITCH, enabled, running, socket_path


@click.group("daemon")
def command() -> None:
    """Show or stop the warm processes that run commands (off with PUPPETCLI_DAEMON=off)."""


@command.command("status")
def status() -> None:
    """List this user's daemons; mark the one serving this installation and environment."""
    mine = socket_path()
    daemons = running()
    for pid, path in daemons:
        serving = " (serves this installation)" if path == mine else ""
        click.echo(f"pid {pid}  {path}{serving}")
    if not daemons:
        click.echo("no daemon running")
    if not enabled():
        click.echo(f"daemons are off here ({SWITCH}={os.environ[SWITCH]})")


@command.command("stop")
def stop() -> None:
    """Stop every daemon of this user (running commands finish)."""
    pids = sorted({pid for pid, _path in running()})
    for pid in pids:
        with contextlib.suppress(ProcessLookupError):  # it ended meanwhile
            os.kill(pid, signal.SIGTERM)
    click.echo(f"stopped {len(pids)} daemon{'s' * (len(pids) != 1)}")
