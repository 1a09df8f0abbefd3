"""``puppetcli validate RIG``: load, validate and summarise a rig."""

from __future__ import annotations

from pathlib import Path

import click
import numpy as np

from puppetcli.rig.load import load_rig
from solver.model import Model, build_model


def summary(model: Model) -> list[str]:
    """Human-readable lines: sizes, mass, rows and the stages the scene needs."""
    nj = model.njoint
    rheo = int(model.joint_rheology.sum())
    limits = (model.joint_swing, model.joint_twist_lo, model.joint_twist_hi)
    limited = int(np.sum(np.any(np.isfinite(limits), axis=0)))
    movable = model.body_inv_mass > 0
    pairs = len(model.geometry.pair_a)
    if not model.has_collision and not model.has_limits:
        solver = "direct (equality rows only)"
    else:
        solver = "PGS when contacts or limits are active, else direct"
    collision = "on" if model.has_collision else "skipped (no pair can touch)"
    opt = model.options
    return [
        f"rig '{model.name}': {len(model.bone_names)} bones, {nj} joints, "
        f"{model.nbody - len(model.bone_names)} dynamic props",
        f"mass: {model.body_mass.sum():.3f} kg in all, "
        f"{model.body_mass[movable].sum():.3f} kg movable",
        f"rows per step: {3 * nj} joint anchor, {3 * rheo} rheology, "
        f"up to {3 * limited} limit; {pairs} shape pairs can collide",
        f"stages: collision {collision}, rheology {'on' if rheo else 'skipped'} ({rheo} joints), "
        f"limits {'on' if model.has_limits else 'skipped'} ({limited} joints), solver {solver}",
        f"step h = {opt.h:g} s, method {opt.method}, {opt.iterations} PGS iterations",
    ]


@click.command("validate")
@click.argument("rig", type=click.Path(exists=True, dir_okay=False, path_type=Path))
def command(rig: Path) -> None:
    """Check a rig file and summarise what its simulation needs."""
    model = build_model(load_rig(rig))
    for line in summary(model):
        click.echo(line)
