"""Grip pose from encoder counts: the device software's damped Gauss–Newton update.

As ``HISpidarCalc6Dof::Update`` (Springhead ``core/src/HumanInterface/HISpidarCalc.cpp``),
once per 1 kHz device tick, warm-started from the previous estimate:

    l_meas = l_home + κ ⊙ c                         (counts → lengths)
    repeat ``iterations`` times (A and the lengths recomputed each time):
        e_i = l_i(p, q) − l_meas,i − b_i            (residual, bias-compensated)
        (AᵀA + σ I) Δx = Aᵀ e,  Δx = (δp, δθ)      (A rows [u_i, r_i × u_i], strings.py)
        p ← p + δp,  q ← exp(δθ) ⊗ q               (rotation applied on the left)
        if angle(q) > angle_max: q ← rotation by angle_max about q's axis
    b ← b + α (l(p, q) − l_meas − b)               (slow length-bias compensation)

The sign follows from δl = −A δx: stepping by Δx changes the computed lengths by −A Δx,
which cancels the residual e.  σ (m⁰ on the position block, m² on the rotation block) is
added to the diagonal: it damps rotation far more than translation, because the rotation
columns scale with the 22.5 mm grip radius.  Calibration at home sets the estimate to
(0, I) and clears the bias; the counts are zero there by construction.

``ideal=True`` gives the comparison estimator: undamped Gauss–Newton iterated to
convergence (step < ``tol``) on the same lengths, without bias or clamp: the
least-squares pose of the quantised lengths.

Velocity (``HIHaptic::Update``, ``HIBase.cpp``), a one-pole low-pass of finite differences:

    v_raw = (p_k − p_{k−1})/dt,   ω_raw = log(q_k ⊗ q_{k−1}⁻¹)/dt   (world-frame ω)
    v ← α_v v + (1 − α_v) v_raw,  ω likewise,   α_v = 0.8 (time constant ≈ 4.5 ticks)

As in Springhead the velocity runs at the start of the tick, before the pose update,
so it differences the two previous estimates (one tick of extra delay).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from puppetcli.spidar.errors import DeviceError
from puppetcli.spidar.presets import DevicePreset
from puppetcli.spidar.strings import ANGLE_MAX, lengths_from_counts, strings_at
from solver import quat

__all__ = ["EstimatorSettings", "PoseEstimator", "Track"]


@dataclass(frozen=True)
class EstimatorSettings:
    """Settings of the device's pose estimator (Springhead ``HISpidarG::Init`` values).

    iterations: Gauss–Newton iterations per tick (``nRepeat``).  damping: σ added to the
    diagonal of AᵀA.  bias_rate: α of the length-bias low-pass (per tick; 0 disables).
    angle_max: rotation clamp from home (rad), None for none (the 2010 code had none).
    velocity_alpha: α_v of the velocity low-pass.  dt: device tick (s).
    """

    iterations: int = 2
    damping: float = 1e-3
    bias_rate: float = 1e-5
    angle_max: float | None = ANGLE_MAX
    velocity_alpha: float = 0.8
    dt: float = 1e-3


@dataclass(frozen=True)
class Track:
    """Estimates over a run of ticks: pos (T,3) m, quat (T,4), velocity (T,3) m/s,
    angular_velocity (T,3) rad/s (world frame), iterations (T,) Gauss–Newton steps."""

    pos: np.ndarray
    quat: np.ndarray
    velocity: np.ndarray
    angular_velocity: np.ndarray
    iterations: np.ndarray


class PoseEstimator:
    """Counts → grip pose, one call per device tick (state: pose, bias, velocity filter)."""

    def __init__(
        self,
        preset: DevicePreset,
        settings: EstimatorSettings | None = None,
        *,
        ideal: bool = False,
        tol: float = 1e-12,
        max_iterations: int = 100,
    ) -> None:
        self.preset = preset
        self.settings = settings or EstimatorSettings()
        s = self.settings
        if s.iterations < 1 or s.damping < 0.0 or not 0.0 <= s.velocity_alpha < 1.0 or s.dt <= 0:
            raise DeviceError(
                "estimator: expected iterations >= 1, damping >= 0, 0 <= velocity_alpha < 1, "
                f"dt > 0, got {s}"
            )
        self.ideal = ideal
        self.tol = tol
        self.max_iterations = max_iterations
        self.calibrate()

    def calibrate(self) -> None:
        """Grip held at home: pose (0, I), bias and velocity cleared."""
        n = self.preset.n_strings
        self.pos = np.zeros(3)
        self.quat = quat.IDENTITY.copy()
        self.bias = np.zeros(n)
        self._last_pos = self.pos.copy()
        self._last_quat = self.quat.copy()
        self._velocity = np.zeros(3)
        self._angular_velocity = np.zeros(3)
        self.last_iterations = 0

    @property
    def velocity(self) -> tuple[np.ndarray, np.ndarray]:
        """Filtered (v (3,) m/s, ω (3,) rad/s, world frame); see the module docstring."""
        return self._velocity.copy(), self._angular_velocity.copy()

    def update(self, counts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """One device tick: encoder counts (n,) → estimated (pos (3,) m, quat (4,))."""
        counts = np.asarray(counts)
        if counts.shape != (self.preset.n_strings,):
            raise DeviceError(
                f"estimator: expected {self.preset.n_strings} counts, got shape {counts.shape}"
            )
        self._update_velocity()
        measured = lengths_from_counts(self.preset, counts)
        if self.ideal:
            self._converge(measured)
        else:
            for _ in range(self.settings.iterations):
                self._step(measured, self.settings.damping, self.settings.angle_max)
            self.last_iterations = self.settings.iterations
            self._update_bias(measured)
        return self.pos.copy(), self.quat.copy()

    def track(self, counts: np.ndarray) -> Track:
        """``update`` over counts (T, n), collecting every tick's estimate and velocity."""
        counts = np.asarray(counts)
        steps = len(counts)
        out = [np.empty((steps, k)) for k in (3, 4, 3, 3)]
        iterations = np.empty(steps, dtype=np.int64)
        for k, row in enumerate(counts):
            out[0][k], out[1][k] = self.update(row)
            out[2][k], out[3][k] = self._velocity, self._angular_velocity
            iterations[k] = self.last_iterations
        return Track(*out, iterations)

    def _step(self, measured: np.ndarray, damping: float, angle_max: float | None) -> float:
        """One damped Gauss–Newton step; returns |Δx| (mixed m and rad)."""
        strings = strings_at(self.preset, self.pos, self.quat)
        a = strings.structure
        residual = strings.length - measured - self.bias
        normal = a.T @ a + damping * np.eye(6)
        dx = np.linalg.solve(normal, a.T @ residual)
        self.pos = self.pos + dx[:3]
        self.quat = quat.normalize(quat.mul(quat.exp(dx[3:]), self.quat))
        if angle_max is not None:
            self.quat = _clamp_angle(self.quat, angle_max)
        return float(np.linalg.norm(dx))

    def _converge(self, measured: np.ndarray) -> None:
        """Undamped Gauss–Newton to convergence (the ideal estimator)."""
        for k in range(1, self.max_iterations + 1):
            if self._step(measured, 0.0, None) < self.tol:
                self.last_iterations = k
                return
        raise DeviceError(
            f"{self.preset.name}: ideal estimator did not converge in "
            f"{self.max_iterations} iterations (lengths unreachable?)"
        )

    def _update_bias(self, measured: np.ndarray) -> None:
        """b ← b + α (l(p, q) − l_meas − b)."""
        alpha = self.settings.bias_rate
        if alpha:
            length = strings_at(self.preset, self.pos, self.quat).length
            self.bias += alpha * (length - measured - self.bias)

    def _update_velocity(self) -> None:
        """Low-passed finite difference of the two latest estimates (before this tick's)."""
        s = self.settings
        v_raw = (self.pos - self._last_pos) / s.dt
        w_raw = quat.log(quat.mul(self.quat, quat.conj(self._last_quat))) / s.dt
        self._velocity = s.velocity_alpha * self._velocity + (1 - s.velocity_alpha) * v_raw
        self._angular_velocity = (
            s.velocity_alpha * self._angular_velocity + (1 - s.velocity_alpha) * w_raw
        )
        self._last_pos = self.pos.copy()
        self._last_quat = self.quat.copy()


def _clamp_angle(q: np.ndarray, angle_max: float) -> np.ndarray:
    """q limited to ``angle_max`` rad from identity about its own axis (shortest arc)."""
    rotvec = quat.log(q)
    angle = float(np.linalg.norm(rotvec))
    if angle <= angle_max:
        return q
    return quat.exp(rotvec * (angle_max / angle))
