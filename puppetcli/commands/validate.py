"""``puppetcli validate RIG``: load, validate and summarise a rig."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import click
import numpy as np

from puppetcli.commands.report import JSON_OPTION, emit
from puppetcli.rig.load import load_rig
from solver.advance import joint_space
from solver.model import Model, Options, build_model


def facts(model: Model) -> dict[str, Any]:
    """Sizes, mass, rows per step and the stages the scene needs, as numbers and words."""
    rheo = int(model.joint_rheology.sum())
    limits = (model.joint_swing, model.joint_twist_lo, model.joint_twist_hi)
    movable = model.body_inv_mass > 0
    opt = model.options
    return {
        "rig": model.name,
        "bones": len(model.bone_names),
        "joints": model.njoint,
        "props": model.nbody - len(model.bone_names),
        "mass": float(model.body_mass.sum()),
        "movable_mass": float(model.body_mass[movable].sum()),
        "rows": {
            "joint_anchor": 3 * model.njoint,
            "rheology": 3 * rheo,
            "limit_at_most": 3 * int(np.sum(np.any(np.isfinite(limits), axis=0))),
        },
        "collision_pairs": len(model.geometry.pair_a),
        "stages": {
            "collision": bool(model.has_collision),
            "rheology_joints": rheo,
            "limits": bool(model.has_limits),
        },
        "h": opt.h,
        "method": opt.method,
        "integrator": opt.integrator,
        "contact_slop": opt.contact_slop,
        "iterations": opt.iterations,
        "warm_start": opt.warm_start,
        "solver": solver_words(model),
    }


def solver_words(model: Model) -> str:
    """What solves each step: the joint-space step when the model qualifies for it
    (solver.advance.joint_space), else the rows' solver as solver.solve.dispatch decides
    it for this scene."""
    if joint_space.unsupported(model) is None:
        return (
            "joint space (a tree of spring-damper joints under bdf2: the articulated-body "
            "recursion along the joints, no rows)"
        )
    return rows_solver_words(model.options, not (model.has_collision or model.has_limits))


def rows_solver_words(opt: Options, two_sided_only: bool) -> str:
    """What solves a step's rows, as solver.solve.dispatch decides it for this scene."""
    sweeps = f"{opt.iterations} PGS sweeps"
    if opt.method == "auto" and two_sided_only:
        return "direct (auto: this scene has two-sided rows only)"
    if opt.method == "auto":
        return (
            f"auto: direct on steps with two-sided rows only, hybrid (two-sided rows exact, "
            f"{sweeps} on contacts and limits) on steps with a contact or limit row"
        )
    if opt.method == "hybrid":
        return f"hybrid: two-sided rows exact, {sweeps} on contacts and limits"
    if opt.method == "pgs":
        warm = f"warm start x{opt.warm_start_factor:g}" if opt.warm_start else "no warm start"
        return f"PGS: {sweeps} over every row, {warm}"
    if opt.method == "direct":
        return "direct (two-sided rows only: a step with a contact or limit row fails)"
    return "reference: a dense exact LCP solve (slow; for tests)"


def summary(f: dict[str, Any]) -> list[str]:
    """The human lines of :func:`facts`."""
    rows, stages = f["rows"], f["stages"]
    collision = (
        f"on (a contact sinks up to {f['contact_slop'] * 1000:g} mm before it pushes back)"
        if stages["collision"]
        else "skipped (no pair can touch)"
    )
    rheo = stages["rheology_joints"]
    limited = rows["limit_at_most"] // 3
    return [
        f"rig '{f['rig']}': {f['bones']} bones, {f['joints']} joints, {f['props']} dynamic props",
        f"mass: {f['mass']:.3f} kg in all, {f['movable_mass']:.3f} kg movable",
        f"rows per step: {rows['joint_anchor']} joint anchor, {rows['rheology']} rheology, "
        f"up to {rows['limit_at_most']} limit; {f['collision_pairs']} shape pairs can collide",
        f"stages: collision {collision}, rheology {'on' if rheo else 'skipped'} ({rheo} joints), "
        f"limits {'on' if stages['limits'] else 'skipped'} ({limited} joints)",
        f"step h = {f['h']:g} s, integrator {f['integrator']}; solver {f['solver']}",
    ]


@click.command("validate")
@click.argument("rig", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@JSON_OPTION
def command(rig: Path, as_json: bool) -> None:
    """Check a rig file and summarise what its simulation needs."""
    f = facts(build_model(load_rig(rig)))
    emit(f, summary(f))
