"""The ``puppetcli`` command group.  Commands live in puppetcli.commands, one module each.

User mistakes (any PuppetError) end as one ``error: …`` line on stderr and exit
status 1, never a traceback.  Modules of the commands are imported only when the
command runs, so ``puppetcli --help`` stays fast.
"""

from __future__ import annotations

import importlib
from typing import NoReturn

import click

from puppetcli.errors import PuppetError, one_line

COMMANDS = {
    "validate": "puppetcli.commands.validate",
    "pose": "puppetcli.commands.pose",
    "bench": "puppetcli.commands.bench",
    "stress": "puppetcli.commands.stress",
    "render": "puppetcli.commands.render",
    "rig": "puppetcli.commands.rig",
    "convert": "puppetcli.commands.convert",
    "record": "puppetcli.commands.record",
    "live": "puppetcli.commands.live",
    "daemon": "puppetcli.commands.daemon",
    "feel": "puppetcli.commands.feel",
    "fit": "puppetcli.commands.fit",
    "batch": "puppetcli.commands.batch",
}
HELP = {
    "validate": "Check a rig file and summarise what its simulation needs.",
    "pose": "Run a manipulation script on a rig: keyframes and a trace.",
    "bench": "Measure steps per second of the solvers on example scenes.",
    "stress": "Check that extreme rigs and inputs simulate stably.",
    "render": "Draw poses: a contact sheet of keys, or a video of a trace.",
    "rig": "Make rigs from other formats (rig from-bvh FILE.bvh, rig from-gltf FILE.glb).",
    "convert": "Run a manipulation script and write the motion as BVH or glTF.",
    "feel": "Measure how a rig's joints feel: effort, retention, spring-back, creep, hold.",
    "fit": "Choose joint coefficients for a feel (retention, spring-back, effort, yield).",
    "record": "Turn a script into the session a SPIDAR-G device would record (.mcap).",
    "live": "Pose the doll by hand in the browser, recorded as a session (.mcap).",
    "daemon": "Show or stop the warm processes that make later commands start fast.",
    "batch": "Run many scripts or sessions at once, locally or on a Dask cluster; resumable.",
}


class LazyGroup(click.Group):
    """A group whose subcommands are imported on use and whose user errors print one line."""

    def list_commands(self, ctx: click.Context) -> list[str]:
        return list(COMMANDS)

    def get_command(self, ctx: click.Context, name: str) -> click.Command | None:
        if name not in COMMANDS:
            return None
        return importlib.import_module(COMMANDS[name]).command

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        with formatter.section("Commands"):
            formatter.write_dl([(name, HELP[name]) for name in COMMANDS])

    def parse_args(self, ctx: click.Context, args: list[str]) -> list[str]:
        try:
            return super().parse_args(ctx, args)
        except click.UsageError as exc:  # `puppetcli --bogus`: the same one line as a command's
            _usage(ctx, exc)

    def invoke(self, ctx: click.Context):
        try:
            return super().invoke(ctx)
        except PuppetError as exc:
            _fail(ctx, one_line(str(exc)), getattr(exc, "exit_code", 1))  # Interrupted: 130
        except KeyboardInterrupt:  # Ctrl-C outside a run (a run saves its part and says so)
            _fail(ctx, "interrupted", 130)
        except click.UsageError as exc:  # a bad option or argument: one line too, status 2
            _usage(ctx, exc)


def _usage(ctx: click.Context, exc: click.UsageError) -> NoReturn:
    """A usage mistake as one line, with the help of the command it concerns; status 2."""
    where = (exc.ctx or ctx).command_path
    _fail(ctx, f"{one_line(exc.format_message())} (see '{where} --help')", 2)


def _fail(ctx: click.Context, message: str, exit_code: int) -> NoReturn:
    """End the command: the one ``error:`` line on stderr (and, with --json, the failure as
    the JSON document on stdout), then the exit status of the README's table."""
    from puppetcli.commands.report import emit_failure

    click.echo(f"error: {message}", err=True)
    emit_failure(ctx, message, exit_code)
    ctx.exit(exit_code)


@click.group(cls=LazyGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="puppetcli")
def cli() -> None:
    """Pose characters like a ball-jointed doll: plastic-joint physics, keyframes, traces."""


def main() -> None:
    """Console entry point."""
    cli(prog_name="puppetcli")
