"""MuJoCo in the work-precision study (``--peers``): its rows and stability lines.

Rows come from ``puppetcli.bench.peers`` (``chain_error``, ``doll_error``): the same chain
and doll grip scenes as ours, one setting per integrator (``mujoco-euler``,
``mujoco-implicitfast``), each against MuJoCo's *own* converged reference (its joints
are Voigt elements, ours three-element: the two engines converge to different motions,
so errors compare in kind, not in value).  MuJoCo's chain is timed over its 3 s run
only; the ``chain-1s`` row's seconds are that time × its share of the steps (a chain
step costs the same all along: no contacts), marked in the note.  There is no creep
peer.

Stability: the doll grip scene (lift over 1 s) at h = 20 and 50 ms, MuJoCo's
``peers.stability`` beside ours (``our_stability``: the compiled step with ``auto``),
with the same figures: finite, largest joint-anchor gap, largest body speed and how
far the gripped tail rose (the lift happened).  A finite run whose fastest body moved
more than RUNAWAY times the pointer's peak speed is called a runaway, not stable.
"""

from __future__ import annotations

import numpy as np

from puppetcli.bench import peers
from puppetcli.bench.precision_row import PrecisionRow
from puppetcli.bench.scenes import CHAIN_TIMES, DOLL_LIFT, DOLL_TIMES, LIFT, doll_model
from puppetcli.bench.solvers import repeats_for
from solver.engine import Engine
from solver.errors import SimulationError
from solver.observe import bone_tails, joint_gaps
from solver.state import initial_state

INTEGRATORS = ("Euler", "implicitfast")
REFERENCE_H, QUICK_REFERENCE_H = peers.REFERENCE_H, 5e-4
STABILITY_H = (0.02, 0.05)
# The pointer's peak speed on the lift (minimum jerk: 15/8 of the mean), and how many
# times faster a body may move before the run counts as a runaway rather than stable:
# with the hips fixed and a 0.4 m/s hand, nothing should move much faster than it.
POINTER_PEAK = 1.875 * float(np.linalg.norm(LIFT)) / DOLL_LIFT
RUNAWAY = 10.0


def _row(scene: str, name: str, r: dict, error: float, steps: int, seconds: float, note=""):
    h = r["h"]
    note = "diverged" if r["diverged"] else note
    return PrecisionRow(scene, name, h, steps, seconds, steps / seconds, steps * h / seconds,
                        error, "m", ref_error=r["ref_error"], note=note)  # fmt: skip


def peer_rows(
    kinds: tuple[str, ...], steps_h: list[float], quick: bool, repeats: int | None = None
) -> list[PrecisionRow]:
    """MuJoCo's rows of the scene kinds ("chain", "doll") at each h, per integrator, each
    timed over ``repeats`` runs, or (None) as many as make a steady timing, the rule of
    our rows (puppetcli.bench.precision)."""
    ref_h = QUICK_REFERENCE_H if quick else REFERENCE_H
    rows = []
    for integrator in INTEGRATORS:
        name = f"mujoco-{integrator.lower()}"
        for h in steps_h:
            if "chain" in kinds:
                runs = repeats or repeats_for(round(CHAIN_TIMES[-1] / h), "mujoco")
                r = peers.chain_error(h, integrator, ref_h, runs)
                share = round(CHAIN_TIMES[0] / h) / r["steps"]
                rows.append(_row("chain-1s", name, r, r["error_1s"], round(CHAIN_TIMES[0] / h),
                                 r["seconds"] * share, "time: share of the 3 s run"))  # fmt: skip
                rows.append(_row("chain-3s", name, r, r["error_3s"], r["steps"], r["seconds"]))
            if "doll" in kinds:
                runs = repeats or repeats_for(round(DOLL_TIMES[-1] / h), "mujoco")
                r = peers.doll_error(h, integrator, ref_h, runs)
                rows.append(_row("doll", name, r, r["error"], r["steps"], r["seconds"]))
    return rows


def our_stability(h: float, seconds: float = DOLL_LIFT, method: str = "auto") -> dict:
    """Our doll grip scene at step h with the compiled step: the figures of
    ``peers.stability`` (finite, max_anchor_gap m, max_speed m/s, grip_rise m), plus
    ``error`` (the SimulationError's message, "" if none)."""
    from puppetcli.bench.scenes import GRIP_BONE, grip_inputs

    model = doll_model().with_options(h=h, method=method)
    n = max(1, round(seconds / h))
    state, gap, speed, error = initial_state(model), 0.0, 0.0, ""
    engine = Engine(model)
    b = model.bone_names.index(GRIP_BONE)
    try:
        for inp in grip_inputs(model, seconds, n):
            state, _ = engine.step(state, inp)
            gap = max(gap, float(np.max(joint_gaps(model, state.body_pos, state.body_quat))))
            speed = max(speed, float(np.max(np.linalg.norm(state.body_vel, axis=1))))
    except SimulationError as exc:
        error = str(exc)
    finite = not error and bool(np.all(np.isfinite(state.body_pos)))
    rise = float(bone_tails(model, state)[b, 1] - model.bone_tail0[b, 1])
    return dict(h=h, steps=n, finite=finite, max_anchor_gap=gap, max_speed=speed,
                grip_rise=rise, error=error)  # fmt: skip


def _verdict(finite: bool, r: dict) -> str:
    if not finite:
        return "UNSTABLE"
    return "runaway" if r["max_speed"] > RUNAWAY * POINTER_PEAK else "stable"


def _figures(r: dict) -> str:
    return (
        f"max anchor gap {r['max_anchor_gap']:.1e} m, max speed {r['max_speed']:.2f} m/s "
        f"({r['max_speed'] / POINTER_PEAK:.1f}× the pointer's peak), "
        f"grip rise {r['grip_rise']:.3f} m"
    )


def stability_lines(with_peers: bool) -> list[str]:
    """One line per (h in STABILITY_H, engine): ours, then MuJoCo's integrators."""
    lines = []
    for h in STABILITY_H:
        ours = our_stability(h)
        state = _verdict(ours["finite"], ours) + (f" ({ours['error'][:60]})" * bool(ours["error"]))
        lines.append(f"stability h={h:g} ours (auto): {state}, {_figures(ours)}")
        for integrator in INTEGRATORS if with_peers else ():
            r = peers.stability(h, DOLL_LIFT, integrator)
            warn = ", ".join(f"{k} ×{v}" for k, v in r["warnings"].items()) or "no warnings"
            state = _verdict(r["finite"] and not r["diverged"], r)
            lines.append(
                f"stability h={h:g} mujoco-{integrator.lower()}: {state} ({warn}), {_figures(r)}"
            )
    return lines
