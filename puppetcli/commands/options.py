"""Command-line options that several commands share, defined once: the same name, type,
default and checks everywhere; each command says in its own words what they act on."""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from typing import Any

import click

from puppetcli.bvh.model import ORDERS
from puppetcli.errors import PuppetError
from puppetcli.render.camera import VIEWS, parse_size, parse_view
from puppetcli.rig.load import STEP_RANGE
from puppetcli.run.warmup import ENGINES
from puppetcli.yamldoc import did_you_mean


class Number(click.FloatRange):
    """A float option in a closed range that must also be finite (click's FloatRange lets NaN
    through, and infinity where a side is open); the range is in the help and the error."""

    def convert(self, value, param, ctx):
        number = super().convert(value, param, ctx)
        if not math.isfinite(number):
            self.fail(f"{value!r} is not a finite number in the range {self._describe_range()}.")
        return number


STEP = Number(*STEP_RANGE)  # s: a physics step, in the range rigs and scripts accept
RATE = Number(1e-3, 1000.0)  # frames per second of a BVH or a video
SCALE = Number(1e-6, 1e6)  # file units per metre


def force_option(what: str):
    """``--force``: overwrite ``what`` when it exists (outputs are kept otherwise)."""
    return click.option("--force", is_flag=True, help=f"Overwrite {what}.")


def order_option(what: str):
    """``--order``: the BVH rotation channel order (any case), ZXY by default."""
    return click.option(
        "--order", type=click.Choice(ORDERS, case_sensitive=False), default="ZXY",
        show_default=True, help=f"Rotation channel order of {what}.",
    )  # fmt: skip


def scale_option(what: str):
    """``--scale``: a BVH length factor, 1 by default."""
    return click.option("--scale", type=SCALE, default=1.0, show_default=True, help=what)


class Parsed(click.ParamType):
    """An option whose text a puppetcli parser reads (``--view``, ``--size``): its error
    becomes click's, so a bad value is a usage error (exit 2) found before any work."""

    def __init__(self, name: str, parse: Callable[[str], Any], choices: tuple[str, ...] = ()):
        self.name, self.parse, self.choices = name, parse, choices

    def shell_complete(self, ctx, param, incomplete: str):
        """Shell completion (docs: README, Shell completion): the named values."""
        from click.shell_completion import CompletionItem

        return [CompletionItem(c) for c in self.choices if c.startswith(incomplete)]

    def convert(self, value, param, ctx):
        if not isinstance(value, str):
            return value
        try:
            return self.parse(value)
        except PuppetError as exc:  # "--view: expected …, got …": click names the option
            self.fail(str(exc).split(": ", 1)[-1] if str(exc).startswith("--") else str(exc))


VIEW = Parsed("view", parse_view, (*VIEWS, "custom:"))
SIZE = Parsed("size", parse_size)


def view_option(what: str):
    """``--view``: a camera of render.camera (front, side, top, iso, custom:AZ,EL[,DIST])."""
    return click.option(
        "--view", type=VIEW, default="iso", show_default=True,
        help=f"Camera of {what}: front, side, top, iso or custom:AZ,EL[,DIST] (degrees, m).",
    )  # fmt: skip


def step_option(what: str, bounds: click.FloatRange = STEP):
    """``--h``: the physics step in seconds (the command's ``step`` argument)."""
    return click.option(
        "--h", "step", type=bounds, default=None, help=f"Physics step (s), overriding {what}."
    )


ENGINE_OPTION = click.option(
    "--engine",
    type=click.Choice(ENGINES),
    default=lambda: os.environ.get("PUPPETCLI_ENGINE", "auto"),
    show_default="auto, or $PUPPETCLI_ENGINE",
    help="Solver: compiled (waits for a first compile), numpy, or auto (numpy until the "
    "compiled solver, built in the background on a first run, is ready).",
)
"""``--engine``: which solver a run steps with (puppetcli.run.warmup)."""

YES_OPTION = click.option(
    "--yes", is_flag=True,
    help="Run even if the run is estimated to take over 10 minutes (refused otherwise).",
)  # fmt: skip
"""``--yes``: accept a run that puppetcli.run.budget estimates as too long."""


def joint_indices(names: tuple[str, ...], asked: tuple[str, ...]) -> list[int]:
    """Indices of the ``--joint`` names asked (all joints when none); a usage error names an
    unknown one."""
    if not names:
        raise click.UsageError("the rig has no joints to measure (one bone, root: fixed)")
    for name in asked:
        if name not in names:
            raise click.BadParameter(
                f"expected a joint of the rig, got {name!r}{did_you_mean(name, names)}",
                param_hint="'--joint'",
            )
    return [names.index(n) for n in dict.fromkeys(asked)] or list(range(len(names)))
