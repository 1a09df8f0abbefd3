"""Coefficients of a joint fitted to recorded data: ``puppetcli fit RIG DATA --joint J``
(docs/feel.md).

Data: a trace's ``/puppet/joints`` (a session is replayed into one first): per step the
joint's rotation θ (rotation vector from rest, rad) and its rheology torque λ (N·m; the
torque acting on the joint's motion is τ = −λ).

Model, per step k → k+1 (Δt = t[k+1] − t[k]), as the simulator discretises it:

    q_f[k+1] = (D_f q_f[k] + Δt τ[k+1]) / (D_f + K_f Δt)     (the Voigt element)
    q_d[k+1] = q_d[k] + Δt τ[k+1] / D_d   while the joint flows, else q_d[k]
    θ_model  = q_f + q_d

The joint flows after its low-passed torque |τ| (time constant ``yield_filter_time``,
the rig's) has passed the yield torque, until it falls below it again (the simulator's
rule; on the step it yields the simulator keeps q_f, and that step's motion joins q_d);
the yield torque is the rig's, not fitted.  The data is taken to start one step after
rest (a trace's first step): q_f[0] is one Voigt step from 0, q_d[0] = θ[0] − q_f[0].
Steps where θ does not change at all (the simulator's sleeping bodies) change nothing.

Fit: scipy's ``least_squares`` of θ_model − θ over every step and axis, in log K_f, log
D_f, log D_d, from the rig's values.  95 % intervals from the Jacobian at the optimum,
σ² (JᵀJ)⁻¹ with σ² = RSS / (n − p), mapped back from the logarithms.  Without a step of
flow in the data D_d is not fitted (kept from the rig).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from puppetcli.errors import PuppetError

__all__ = ["Identified", "IdentifyError", "identify", "joint_series", "simulate"]

Z95 = 1.959964  # two-sided 95 % normal quantile
MIN_STEPS = 20


class IdentifyError(PuppetError):
    """Data that cannot give a joint's coefficients."""


@dataclass(frozen=True)
class Identified:
    """kf, df, dd: the fitted coefficients; low, high: their 95 % intervals (3,); rms:
    residual angle (rad); flows: steps of flow in the data; times (n,), measured and
    model (n,3) angles (rad) for the residual plot; fitted: which were fitted."""

    kf: float
    df: float
    dd: float
    low: np.ndarray
    high: np.ndarray
    rms: float
    flows: int
    times: np.ndarray
    measured: np.ndarray
    model: np.ndarray
    fitted: tuple[str, ...]


def joint_series(data: dict, joint: str, source: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(times (n,) s, rotations (n,3) rad, torques τ = −λ (n,3) N·m) of ``joint`` in a
    trace read by ``puppetcli.mcap.trace.read_trace``."""
    messages = data.get("/puppet/joints") or []
    if len(messages) < MIN_STEPS:
        raise IdentifyError(f"{source}: /puppet/joints: expected at least {MIN_STEPS} steps of "
                            f"joint angles and torques, got {len(messages)}")  # fmt: skip
    t, rot, tau = [], [], []
    for ns, msg in messages:
        try:
            j = msg["joints"][joint]
            rot.append([float(v) for v in j["rotation"]])
            tau.append([-float(v) for v in j["torque"]])
        except (KeyError, TypeError, ValueError):
            raise IdentifyError(f"{source}: /puppet/joints at {ns / 1e9:.6g} s: expected the "
                                f"rotation and torque of joint {joint!r}") from None  # fmt: skip
        t.append(ns / 1e9)
    out = np.array(t), np.array(rot).reshape(-1, 3), np.array(tau).reshape(-1, 3)
    if not all(np.all(np.isfinite(a)) for a in out) or np.any(np.diff(out[0]) <= 0.0):
        raise IdentifyError(f"{source}: /puppet/joints: expected finite values at increasing "
                            "times")  # fmt: skip
    return out


def flow_steps(
    t: np.ndarray, tau: np.ndarray, yield_: float, filter_time: float
) -> tuple[np.ndarray, np.ndarray]:
    """(whether the joint flows in each step: the yield flag before it; whether it yields
    during the step: the flag turning on), (n,) bool each."""
    n = len(t)
    flows, onset = np.zeros(n, dtype=bool), np.zeros(n, dtype=bool)
    if not math.isfinite(yield_):
        flows[1:] = True
        return flows, onset
    size = np.linalg.norm(tau, axis=1)
    avg, yielded = 0.0, False
    for k in range(1, n):
        flows[k] = yielded
        dt = t[k] - t[k - 1]
        avg += dt / (filter_time + dt) * (size[k] - avg)
        yielded = (avg >= yield_) if yielded else (avg > yield_)
        onset[k] = yielded and not flows[k]
    return flows, onset


def simulate(params: np.ndarray, t: np.ndarray, tau: np.ndarray, theta0: np.ndarray,
             steps: tuple[np.ndarray, np.ndarray, np.ndarray]) -> np.ndarray:  # fmt: skip
    """θ_model (n,3) for (K_f, D_f, D_d) ``params`` and ``flow_steps``' result (see the
    module docstring; on the step a joint yields, the simulator keeps q_f and the step's
    motion joins q_d)."""
    kf, df, dd = params
    flows, onset, frozen = steps
    dt0 = t[1] - t[0]
    q_f = dt0 * tau[0] / (df + kf * dt0)  # one step from rest
    q_d = theta0 - q_f
    out = np.empty_like(tau)
    out[0] = theta0
    for k in range(1, len(t)):
        dt = t[k] - t[k - 1]
        if frozen[k]:  # the simulator put the joint's bodies to sleep
            out[k] = q_f + q_d
            continue
        voigt = (df * q_f + dt * tau[k]) / (df + kf * dt)
        if onset[k]:
            q_d = q_d + voigt - q_f
        else:
            q_f = voigt
        if flows[k]:
            q_d = q_d + dt * tau[k] / dd
        out[k] = q_f + q_d
    return out


def identify(
    t: np.ndarray,
    theta: np.ndarray,
    tau: np.ndarray,
    start: tuple[float, float, float],
    yield_: float,
    filter_time: float,
    joint: str,
) -> Identified:
    """Least squares of the model on the data (see the module docstring)."""
    from scipy.optimize import least_squares

    frozen = np.r_[False, np.all(np.diff(theta, axis=0) == 0.0, axis=1)]
    steps = (*flow_steps(t, tau, yield_, filter_time), frozen)
    flows = steps[0] & ~frozen
    free = ("kf", "df", "dd") if flows.any() else ("kf", "df")
    start = tuple(float(v) if math.isfinite(v) and v > 0.0 else 1.0 for v in start)
    fixed = dict(zip(("kf", "df", "dd"), start, strict=True))

    def params(x: np.ndarray) -> np.ndarray:
        values = dict(fixed) | dict(zip(free, np.exp(x), strict=True))
        return np.array([values["kf"], values["df"], values["dd"]])

    def residuals(x: np.ndarray) -> np.ndarray:
        return (simulate(params(x), t, tau, theta[0], steps) - theta).ravel()

    x0 = np.log([fixed[n] for n in free])
    fit = least_squares(residuals, x0, x_scale=1.0, xtol=1e-12, ftol=1e-12, gtol=1e-12,
                        max_nfev=200)  # fmt: skip
    n, p = fit.fun.size, len(free)
    if n <= p:
        raise IdentifyError(f"{joint}: expected more samples than coefficients, got {n}")
    sigma2 = float(fit.fun @ fit.fun) / (n - p)
    try:
        cov = sigma2 * np.linalg.inv(fit.jac.T @ fit.jac)
        half = Z95 * np.sqrt(np.clip(np.diag(cov), 0.0, None))
    except np.linalg.LinAlgError:
        half = np.full(p, np.inf)
    values = params(fit.x)
    low, high = values.copy(), values.copy()
    for k, name in enumerate(free):
        i = ("kf", "df", "dd").index(name)
        low[i], high[i] = math.exp(fit.x[k] - half[k]), math.exp(fit.x[k] + half[k])
    model = simulate(values, t, tau, theta[0], steps)
    return Identified(float(values[0]), float(values[1]), float(values[2]), low, high,
                      math.sqrt(sigma2), int(flows.sum()), t, theta, model, free)  # fmt: skip
