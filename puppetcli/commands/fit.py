"""``puppetcli fit RIG -o RIG2.yaml --target retention=0.9 …``: joint coefficients chosen
for a feel."""

from __future__ import annotations

import math
import re
from pathlib import Path

import click
import numpy as np

from puppetcli.commands.options import (
    ENGINE_OPTION,
    YES_OPTION,
    Number,
    force_option,
    joint_indices,
)  # fmt: skip
from puppetcli.commands.report import JSON_OPTION, emit, progress_bar
from puppetcli.errors import shown
from puppetcli.feel.fit import NAMES, Solved, Target, fit_joint, measured
from puppetcli.feel.identify import identify, joint_series
from puppetcli.feel.measure import AxisFeel, axes, measure_axis
from puppetcli.feel.plot import fit_png, write_plots
from puppetcli.feel.report import aligned
from puppetcli.feel.rigfile import rig_with_joints
from puppetcli.mcap.session import is_session
from puppetcli.mcap.trace import read_trace
from puppetcli.outputs import refuse_overwrite
from puppetcli.rig.load import load_rig, rig_from_text
from puppetcli.rig.make import write_rig
from puppetcli.run.session_trace import session_trace
from puppetcli.run.warmup import prepare_engine
from solver.model import Model, build_model

UNITS = {  # name → {unit suffix: factor}
    "retention": {"": 1.0, "%": 0.01},
    "springback": {"s": 1.0, "ms": 0.001},
    "effort": {"N": 1.0, "Nm": 1.0, "N·m": 1.0},
    "yield": {"Nm": 1.0, "N·m": 1.0, "": 1.0},
}
_TARGET = re.compile(
    r"^(?:(?P<joint>[^=]+)\.)?(?P<name>[a-z]+)=(?P<value>[-+0-9.eE]+)(?P<unit>.*)$"
)


def parse_target(text: str) -> Target:
    """``[JOINT.]NAME=VALUE[UNIT]`` (e.g. ``forearm_l.effort=12N``, ``springback=80ms``)."""
    m = _TARGET.match(text.strip())
    hint = "'--target'"
    if m is None:
        raise click.BadParameter(f"expected [JOINT.]NAME=VALUE[UNIT], got {shown(text)}",
                                 param_hint=hint)  # fmt: skip
    name, unit = m["name"], m["unit"].strip()
    if name not in NAMES:
        raise click.BadParameter(f"expected one of {', '.join(NAMES)}, got {shown(name)}",
                                 param_hint=hint)  # fmt: skip
    if unit not in UNITS[name]:
        units = ", ".join(repr(u) for u in UNITS[name])
        raise click.BadParameter(f"{name}: expected a unit among {units}, got {shown(unit)}",
                                 param_hint=hint)  # fmt: skip
    try:
        value = float(m["value"]) * UNITS[name][unit]
    except ValueError:
        raise click.BadParameter(f"{name}: expected a number, got {shown(m['value'])}",
                                 param_hint=hint) from None  # fmt: skip
    ok = 0.0 < value < 1.0 if name == "retention" else 0.0 < value < 1e6
    if not (math.isfinite(value) and ok):
        want = "a share between 0 and 1" if name == "retention" else "a positive amount"
        raise click.BadParameter(f"{name}: expected {want}, got {shown(text)}", param_hint=hint)
    return Target(m["joint"], name, value, force=(name == "effort" and unit == "N"))


@click.command("fit")
@click.argument("rig", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.argument(
    "data", required=False, type=click.Path(exists=True, dir_okay=False, path_type=Path)
)
@click.option("-o", "--out", required=True, type=click.Path(dir_okay=False, path_type=Path),
              help="The rig to write (YAML).")  # fmt: skip
@click.option(
    "--target", "targets", multiple=True,
    help="[JOINT.]NAME=VALUE[UNIT]: retention=0.9, springback=0.2s, effort=15N (at the bone's "
    "tip) or effort=4Nm, yield=8Nm; without JOINT. for every joint fitted.",
)  # fmt: skip
@click.option(
    "--joint",
    "joints",
    multiple=True,
    help="Fit this joint (repeat) [default: the joints the targets name, else all].",
)
@click.option("--angle", type=Number(1.0, 90.0), default=30.0, show_default=True,
              help="The bend the measures use, degrees (as feel).")  # fmt: skip
@click.option("--time", "duration", type=Number(0.05, 10.0), default=1.0, show_default=True,
              help="Seconds the bend takes (as feel).")  # fmt: skip
@click.option(
    "--plot",
    "plot_dir",
    type=click.Path(file_okay=False, path_type=Path),
    help="With DATA: write DIR/JOINT-fit.png, the angle and the fitted model's.",
)
@force_option("RIG2.yaml if it exists")
@YES_OPTION
@ENGINE_OPTION
@JSON_OPTION
def command(
    rig: Path, data: Path | None, out: Path, targets: tuple[str, ...], joints: tuple[str, ...],
    angle: float, duration: float, plot_dir: Path | None, force: bool, yes: bool, engine: str,
    as_json: bool,
) -> None:  # fmt: skip
    """Choose K_f, D_f, D_d and the yield torque of joints, and write the rig with them:
    for target measures (--target), or fitted to recorded DATA.

    With --target, each joint is solved with the three-element model's closed form, then
    fitted to the targets as a simulation of the rig measures them (as `feel` does, on the
    swing axis).  With DATA (a trace .mcap, or a session .mcap, replayed first), K_f, D_f
    and D_d of each --joint are fitted by least squares to the joint's recorded angles and
    torques, with 95 % intervals.  The new rig has a comment above each fitted bone.  See
    docs/feel.md.
    """
    if data is not None:
        if targets:
            raise click.UsageError("give --target or DATA, not both")
        refuse_overwrite(out, force)
        _fit_data(rig, data, out, joints, plot_dir, yes)
        return
    if not targets:
        raise click.UsageError("nothing to fit to: give --target NAME=VALUE or a DATA file")
    parsed = [parse_target(t) for t in targets]
    refuse_overwrite(out, force)
    text = rig.read_text(encoding="utf-8")
    spec = load_rig(rig)
    base, _ = prepare_engine(build_model(spec), engine, rig)
    named = tuple(t.joint for t in parsed if t.joint)
    wanted = joint_indices(base.joint_names, joints or named)
    a_rad = math.radians(angle)

    def build(j: int, solved: Solved) -> Model:
        changed = rig_with_joints(text, {base.joint_names[j]: _coefficients(solved)})
        model = build_model(rig_from_text(changed, str(rig)))
        return model.with_options(engine=base.options.engine)

    results, rows = {}, []
    with progress_bar("fitting", len(wanted)) as tick:
        for j in wanted:
            goals = _goals(base, j, parsed)
            if not goals:
                continue
            a = axes(base, j)["swing"]
            before = measure_axis(base, j, "swing", a, a_rad, duration)
            solved = fit_joint(base, j, goals, a_rad, duration, build)
            results[base.joint_names[j]] = solved
            rows += _rows(base.joint_names[j], goals, before, solved)
            if tick:
                tick(1)
    comments = {n: _comment(n, rows) for n in results}
    new_text = rig_with_joints(text, {n: _coefficients(s) for n, s in results.items()}, comments)
    write_rig(out, new_text)
    emit({"rig": str(rig), "out": str(out), "fits": rows},
         [_table(rows), f"wrote {out}: {len(results)} joints fitted"])  # fmt: skip


def _fit_data(
    rig: Path, data: Path, out: Path, joints: tuple[str, ...], plot_dir: Path | None, yes: bool
) -> None:
    """The data mode: every --joint fitted to DATA's angles and torques."""
    if not joints:
        raise click.UsageError("DATA needs --joint J (the joints to fit)")
    spec = load_rig(rig)
    model = build_model(spec)
    wanted = joint_indices(model.joint_names, joints)
    trace = session_trace(data, spec, yes, read_trace) if is_session(data) else read_trace(data)
    found, lines, comments = {}, [], {}
    for j in wanted:
        name = model.joint_names[j]
        t, theta, tau = joint_series(trace, name, str(data))
        start = tuple(
            float(np.mean(c[j])) for c in (model.joint_kf, model.joint_df, model.joint_dd)
        )
        fit = identify(t, theta, tau, start, float(model.joint_yield[j]),
                       model.options.yield_filter_time, name)  # fmt: skip
        found[name] = fit
        found_text = ", ".join(
            f"{k} {v:.4g} [{lo:.4g}, {hi:.4g}]"
            for k, v, lo, hi in zip(("kf", "df", "dd"), (fit.kf, fit.df, fit.dd), fit.low,
                                    fit.high, strict=True))  # fmt: skip
        comments[name] = f"fitted by `puppetcli fit` to {data.name}: {found_text}"
        lines.append(f"{name}: {data.name}: {found_text} (95 %), residual {fit.rms:.3g} rad rms "
                     f"over {len(t)} steps, {fit.flows} flowing")  # fmt: skip
    text = rig.read_text(encoding="utf-8")
    coefficients = {n: {"kf": f.kf, "df": f.df, "dd": f.dd} for n, f in found.items()}
    new_text = rig_with_joints(text, coefficients, comments)
    write_rig(out, new_text)
    written = [str(out)]
    if plot_dir is not None:
        written += write_plots(plot_dir, {f"{n}-fit": fit_png(n, f) for n, f in found.items()})
    facts = {"rig": str(rig), "data": str(data), "out": str(out), "written": written,
             "fits": {n: {"kf": f.kf, "df": f.df, "dd": f.dd, "low": f.low.tolist(),
                          "high": f.high.tolist(), "rms": f.rms, "flowing_steps": f.flows,
                          "fitted": list(f.fitted)} for n, f in found.items()}}  # fmt: skip
    emit(facts, [*lines, *(f"wrote {w}" for w in written)])


def _coefficients(s: Solved) -> dict[str, float]:
    return {"kf": s.kf, "df": s.df, "dd": s.dd, "yield": s.yield_}


def _goals(model: Model, j: int, parsed: list[Target]) -> dict[str, float]:
    """The joint's targets (its own over the global ones), effort as N·m."""
    b = model.joint_bone[j]
    length = float(np.linalg.norm(model.bone_tail0[b] - model.bone_head0[b]))
    goals = {}
    for t in sorted(parsed, key=lambda t: t.joint is not None):  # own targets last: they win
        if t.joint not in (None, model.joint_names[j]):
            continue
        if t.force and length < 1e-9:
            raise click.BadParameter(
                f"{model.joint_names[j]}: effort in N needs a bone with a "
                "length (its tip); give it in Nm",
                param_hint="'--target'",
            )
        goals[t.name] = t.value * length if t.force else t.value
    return goals


def _rows(joint: str, goals: dict, before: AxisFeel, solved: Solved) -> list[dict]:
    return [{"joint": joint, "target": name, "goal": goal, "before": measured(before, name),
             "after": measured(solved.measured, name), "kf": solved.kf, "df": solved.df,
             "dd": solved.dd, "yield": solved.yield_} for name, goal in goals.items()]  # fmt: skip


def _comment(joint: str, rows: list[dict]) -> str:
    parts = [f"{r['target']} {r['goal']:.4g} (now {r['after']:.4g})" for r in rows
             if r["joint"] == joint]  # fmt: skip
    return "fitted by `puppetcli fit`: " + ", ".join(parts)


def _table(rows: list[dict]) -> str:
    head = ["joint", "target", "goal", "before", "after", "kf", "df", "dd", "yield"]
    body = [[r["joint"], r["target"]] + [f"{r[k]:.4g}" for k in head[2:]] for r in rows]
    return aligned([head, *body])
