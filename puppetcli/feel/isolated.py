"""The three-element joint on its own: what ``feel`` measures, predicted without neighbours,
gravity or inertia (docs/feel.md).

One axis of a joint: a Voigt element (spring K_f ∥ damper D_f, elastic angle q_f) in
series with a damper D_d (plastic angle q_d), the whole angle θ = q_f + q_d, the torque

    τ = K_f q_f + D_f q̇_f = D_d q̇_d        (flowing),

and, below the yield torque τ_y (and before it is first reached), no flow: q̇_d = 0,
τ = K_f q_f + D_f q̇_f.  (The simulation compares a low-pass of |τ| with τ_y; this model
switches on τ itself.)

Bent along a prescribed θ(t) (``bend``): flowing, (D_f + D_d) q̇_f = D_d θ̇ − K_f q_f; not
flowing, q_f = θ − q_d.  Integrated exactly per step for a piecewise-linear θ(t)
(the equation is linear with constant coefficients; the step's exact solution is used).

Released (τ = 0): q̇_d = 0 and q_f decays as e^(−t/T_r), T_r = D_f / K_f, so the joint
springs back by q_f(release) and keeps θ − q_f:

    retention(t) = (θ_r − q_f,r (1 − e^(−t/T_r))) / θ_r.

Held at a constant torque τ (``creep_rate``): q_f → τ / K_f with T_r, and, flowing,
q_d grows at τ / D_d: the creep rate; not flowing (τ ≤ τ_y), no creep.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["Bend", "IsolatedJoint", "min_jerk"]


def min_jerk(s: np.ndarray) -> np.ndarray:
    """Fraction done of a minimum-jerk motion at s = t / duration in [0, 1]."""
    s = np.clip(s, 0.0, 1.0)
    return s**3 * (10.0 - 15.0 * s + 6.0 * s**2)


@dataclass(frozen=True)
class Bend:
    """The isolated joint's response to a bend: times (n,) s, angle θ, elastic part q_f
    (rad) and torque τ (N·m) at those times; flows: whether it flowed at all."""

    times: np.ndarray
    angle: np.ndarray
    elastic: np.ndarray
    torque: np.ndarray
    flows: bool

    @property
    def peak_torque(self) -> float:
        return float(np.max(np.abs(self.torque)))


@dataclass(frozen=True)
class IsolatedJoint:
    """One axis: kf N·m/rad, df N·m·s/rad, dd N·m·s/rad (inf: never flows), yield_ N·m
    (inf: none, it always flows)."""

    kf: float
    df: float
    dd: float
    yield_: float

    @property
    def springback_time(self) -> float:
        """T_r = D_f / K_f (s); inf for a joint without a spring."""
        return self.df / self.kf if self.kf > 0.0 else math.inf

    def flows_at(self, torque: float) -> bool:
        finite_yield = math.isfinite(self.yield_)
        return math.isfinite(self.dd) and (not finite_yield or abs(torque) > self.yield_)

    def bend(self, angle: float, duration: float, steps: int = 20000) -> Bend:
        """Bent by ``angle`` rad over ``duration`` s along a minimum-jerk profile (what
        ``rotate`` and ``twist`` do), from rest."""
        t = np.linspace(0.0, duration, steps + 1)
        theta = angle * min_jerk(t / duration)
        q_f = np.zeros_like(t)
        tau = np.zeros_like(t)
        q_d, flowing, ever = 0.0, not math.isfinite(self.yield_) and math.isfinite(self.dd), False
        for k in range(1, len(t)):
            dt, rate = t[k] - t[k - 1], (theta[k] - theta[k - 1]) / (t[k] - t[k - 1])
            if flowing:
                q_f[k] = self._flow_step(q_f[k - 1], rate, dt)
                q_d = theta[k] - q_f[k]
                tau[k] = self.dd * (rate - (q_f[k] - q_f[k - 1]) / dt)
                flowing = self.flows_at(tau[k])  # below the yield torque again: it stops
            else:
                q_f[k] = theta[k] - q_d
                tau[k] = self.kf * q_f[k] + self.df * rate
                flowing = self.flows_at(tau[k])
            ever = ever or flowing
        return Bend(t, theta, q_f, tau, ever)

    def _flow_step(self, q_f: float, rate: float, dt: float) -> float:
        """Exact solution over dt of (D_f + D_d) q̇_f = D_d·rate − K_f q_f."""
        c = self.df + self.dd
        if self.kf <= 0.0:
            return q_f + self.dd * rate * dt / c
        target = self.dd * rate / self.kf
        return target + (q_f - target) * math.exp(-self.kf * dt / c)

    def retention(self, bend: Bend, after: float) -> float:
        """Share of the bend kept ``after`` s after release at the bend's end."""
        theta, q_f = float(bend.angle[-1]), float(bend.elastic[-1])
        decay = 1.0 - math.exp(-after / self.springback_time) if self.kf > 0.0 else 0.0
        return (theta - q_f * decay) / theta

    def creep_rate(self, torque: float) -> float:
        """rad/s under a constant ``torque``: τ / D_d when it flows, else 0."""
        return abs(torque) / self.dd if self.flows_at(torque) else 0.0
