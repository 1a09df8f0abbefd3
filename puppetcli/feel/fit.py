"""Coefficients chosen for a feel: ``puppetcli fit RIG --target …`` (docs/feel.md).

Targets (``Target``) are the measures of ``feel`` on a joint's swing axis: *retention*
(share kept 2 s after the bend), *springback* (its time constant, s), *effort* (the peak
torque of the bend, N·m, or the force at the bone's tip, N) and *yield* (N·m).

First the isolated joint (``puppetcli.feel.isolated``), in closed form:

- the spring-back time constant is D_f / K_f, so D_f = T·K_f;
- scaling K_f, D_f, D_d and the yield torque by one factor scales every torque and
  leaves every angle (so retention and T) alone: the effort fixes that factor;
- retention then depends on D_d / K_f alone (T and yield / K_f held): a root of a
  monotone function, found with scipy's ``brentq``;
- a yield target sets the yield torque.

A measure the user did not target keeps the rig's value of its coefficient ratio.  Then
the rig is simulated (``measure_axis``) and each target the isolated joint was solved
for is corrected by what the neighbours did (effort and T by their ratio,
retention by its difference), the closed form solved again, up to ``REFINE`` times or
until every target is met within ``MET``.  All three axes of the joint get the same
coefficients.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from puppetcli.errors import PuppetError
from puppetcli.feel.isolated import IsolatedJoint
from puppetcli.feel.measure import RETAIN, AxisFeel, axes, isolated_joint, measure_axis
from solver.model import Model

__all__ = [
    "MEASURES", "NAMES", "FitError", "Solved", "Target", "fit_joint", "measured",
    "solve_closed_form",
]  # fmt: skip

# target name → the AxisFeel measure it sets
MEASURES = {"retention": "retention", "springback": "springback_time", "effort": "effort",
            "yield": "flow_onset"}  # fmt: skip
NAMES = tuple(MEASURES)
REFINE = 5  # simulation passes at most
DAMPING = 0.8  # share of a correction taken per pass
MET = 0.01  # relative (retention: absolute) distance at which a target counts as met
RATIO_RANGE = (1e-4, 1e4)  # D_d / K_f searched (s)


class FitError(PuppetError):
    """A target the joint cannot reach."""


@dataclass(frozen=True)
class Target:
    """joint: a joint name or None (every joint); name: one of NAMES; value: fraction,
    s or N·m; force: True when an effort was given in N at the bone's tip."""

    joint: str | None
    name: str
    value: float
    force: bool = False


@dataclass(frozen=True)
class Solved:
    """A joint's coefficients (one value for all axes) and, after the simulation, its
    measure and how far each target is from it."""

    kf: float
    df: float
    dd: float
    yield_: float
    measured: AxisFeel | None = None
    misses: dict[str, float] | None = None


def solve_closed_form(
    start: IsolatedJoint, goals: dict[str, float], angle: float, duration: float, where: str
) -> IsolatedJoint:
    """The isolated joint that meets ``goals`` (name → value; effort in N·m), the others
    kept from ``start`` (see the module docstring): K_f = s·K_f0, D_f = T·K_f,
    D_d = ρ·K_f, the yield torque absolute; ρ and s solved by least squares (scipy) on
    the retention and effort goals."""
    from scipy.optimize import least_squares

    kf0 = start.kf if start.kf > 0.0 else 1.0
    tr = goals.get("springback", start.springback_time if start.kf > 0.0 else 0.05)
    rho0 = start.dd / kf0 if math.isfinite(start.dd) else 10.0 * tr
    y = goals.get("yield", start.yield_)

    def joint(log_rho: float, log_s: float) -> IsolatedJoint:
        kf = kf0 * math.exp(log_s)
        return IsolatedJoint(kf, kf * tr, kf * math.exp(log_rho), y)

    free = [n for n in ("retention", "effort") if n in goals]
    if not free:
        return joint(math.log(rho0), 0.0)

    def unpack(x: np.ndarray) -> tuple[float, float]:
        values = dict(zip(free, x, strict=True))
        return values.get("retention", math.log(rho0)), values.get("effort", 0.0)

    def residuals(x: np.ndarray) -> np.ndarray:
        iso = joint(*unpack(x))
        bend = iso.bend(angle, duration, steps=2000)
        out = []
        if "retention" in goals:
            out.append(iso.retention(bend, RETAIN) - goals["retention"])
        if "effort" in goals:
            out.append(math.log(max(bend.peak_torque, 1e-300) / goals["effort"]))
        return np.array(out)

    lo, hi = math.log(RATIO_RANGE[0]), math.log(RATIO_RANGE[1])
    # The yield switch makes the residuals kinked: start from the best point of a grid.
    grid = {"retention": np.linspace(lo, hi, 17), "effort": np.linspace(-5.0, 5.0, 11)}
    starts = np.stack(np.meshgrid(*[grid[n] for n in free]), axis=-1).reshape(-1, len(free))
    x0 = min(starts, key=lambda x: float(np.sum(residuals(x) ** 2)))
    bounds = ([lo if n == "retention" else -12.0 for n in free],
              [hi if n == "retention" else 12.0 for n in free])  # fmt: skip
    fit = least_squares(residuals, x0, bounds=bounds, xtol=1e-12, ftol=1e-12)
    if np.max(np.abs(fit.fun)) > 1e-4:
        reached = {n: float(v) for n, v in zip(free, fit.fun, strict=True)}
        raise FitError(
            f"{where}: expected targets the three-element joint can meet (with spring-back "
            f"time {tr:.3g} s and yield {y:.3g} N·m), got {_describe(goals)}: closest misses "
            f"by {reached}"
        )
    return joint(*unpack(fit.x))


def _describe(goals: dict[str, float]) -> str:
    return ", ".join(f"{n}={v:.4g}" for n, v in goals.items())


def measured(a: AxisFeel, name: str) -> float:
    """The measure of ``a`` that target ``name`` is about (``MEASURES``)."""
    return float(getattr(a, MEASURES[name]))


def _miss(name: str, measured: float, goal: float) -> float:
    if not math.isfinite(measured):
        return math.inf
    return abs(measured - goal) if name == "retention" else abs(measured / goal - 1.0)


def fit_joint(
    model: Model,
    j: int,
    goals: dict[str, float],
    angle: float,
    duration: float,
    build,
) -> Solved:
    """Coefficients of joint ``j`` for ``goals`` (effort in N·m); ``build(j, solved)``
    returns the rig's Model with them.  The closed form's joint is the start of a least-
    squares fit (scipy) of the free coefficients to the goals as the simulation measures
    them (at most ``REFINE`` Jacobians)."""
    from scipy.optimize import least_squares

    a = axes(model, j)["swing"]
    start = isolated_joint(model, j, a)
    iso = solve_closed_form(start, goals, angle, duration, model.joint_names[j])
    free = [n for n in ("retention", "effort", "springback") if n in goals]
    y = goals.get("yield", iso.yield_)
    tried: list[Solved] = []

    def coefficients(x: np.ndarray) -> Solved:
        v = dict(zip(free, np.exp(x), strict=True))
        kf = iso.kf * v.get("effort", 1.0)
        tr = iso.springback_time * v.get("springback", 1.0)
        rho = iso.dd / iso.kf * v.get("retention", 1.0)
        return Solved(kf, kf * tr, kf * rho, y)

    def residuals(x: np.ndarray) -> np.ndarray:
        solved = coefficients(x)
        found = measure_axis(build(j, solved), j, "swing", a, angle, duration, quick=True)
        misses = {n: _miss(n, measured(found, n), g) for n, g in goals.items()}
        tried.append(replace(solved, measured=found, misses=misses))
        out = []
        for n in free:
            m = measured(found, n)
            if not (math.isfinite(m) and m > -1.0):
                return np.full(len(free), 1e3)
            out.append(m - goals[n] if n == "retention" else math.log(max(m, 1e-300) / goals[n]))
        return np.array(out)

    x0 = np.zeros(len(free))
    if free and np.max(np.abs(residuals(x0))) > MET:
        least_squares(residuals, x0, diff_step=1e-3, max_nfev=REFINE * (len(free) + 1),
                      xtol=1e-8, ftol=1e-10)  # fmt: skip
    elif not free:
        residuals(x0)
    return min(tried, key=lambda s: max(s.misses.values()))
