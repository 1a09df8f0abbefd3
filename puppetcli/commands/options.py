"""Command-line options that several commands share, defined once: the same name, type,
default and checks everywhere; each command says in its own words what they act on."""

from __future__ import annotations

import os

import click

from puppetcli.bvh.model import ORDERS
from puppetcli.run.warmup import ENGINES

POSITIVE = click.FloatRange(min=0.0, min_open=True)


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
    return click.option("--scale", type=POSITIVE, default=1.0, show_default=True, help=what)


def view_option(what: str):
    """``--view``: a camera of render.camera (front, side, top, iso, custom:AZ,EL[,DIST])."""
    return click.option(
        "--view", default="iso", show_default=True,
        help=f"Camera of {what}: front, side, top, iso or custom:AZ,EL[,DIST] (degrees, m).",
    )  # fmt: skip


def step_option(what: str, bounds: click.FloatRange = POSITIVE):
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
