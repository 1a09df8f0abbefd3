"""Tensions for a wanted wrench, and the wrench the strings really display.

Statics (strings.py): tensions t (n,), t_i ≥ 0 pulling the grip toward m_i, put the wrench
W = (f, τ) = Aᵀ t on the grip (τ about the grip centre, device frame).  With 8 strings
and 6 DOF, Aᵀ has a 2-D null space (internal pre-tension).  Springhead's
``HISpidarCalc6Dof::SetForce`` picks t by the box-constrained QP

    minimise  λ_t |f_d − U t|² + λ_r |τ_d − M t|² + s |t|²   s.t.  t_min ≤ t_i ≤ t_max
    U = [u_1 … u_n] (3×n),  M = [w_1 … w_n] (3×n),  (Aᵀ = [U; M])
    ⇔  ½ tᵀQt − cᵀt,  Q = λ_t UᵀU + λ_r MᵀM + s I,  c = λ_t Uᵀf_d + λ_r Mᵀτ_d

(the factor 2 is dropped: same minimiser), i.e. ‖Aᵀt − W_d‖²_Λ + s‖t‖² with
Λ = diag(λ_t I₃, λ_r I₃).  Weights s = 0.3, λ_t = 1, λ_r = 6 (``HISpidarG::SetWeight``).
The regulariser s > 0 makes Q positive definite, so the optimum is unique.  The device
displays W_disp = Aᵀ t*, never W_d: a wrench beyond what the strings can make is
attenuated (and the QP attenuates even feasible ones: s trades accuracy for low tension).

``capacity`` answers what the strings can make at all: for each axis and sign the largest
pure force (zero torque, zero other components) or pure torque, by linear programming.
``least_capacity`` is the force and the torque the device can display whichever way they
point: the least such maximum over the 26 directions of a cube's faces, edges and
corners (an edge or corner direction needs several strings at once, and is often the
weakest).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from puppetcli.spidar.boxqp import solve_box_qp
from puppetcli.spidar.errors import DeviceError
from puppetcli.spidar.presets import DevicePreset
from puppetcli.spidar.strings import structure_matrix
from solver import quat

__all__ = [
    "TensionDistributor",
    "TensionResult",
    "TensionWeights",
    "capacity",
    "least_capacity",
    "motor_volts",
    "solve_tensions",
]


@dataclass(frozen=True)
class TensionWeights:
    """QP weights (Springhead's units: squared N, squared N·m and squared N all summed):
    force λ_t, torque λ_r, regulariser s > 0."""

    force: float = 1.0
    torque: float = 6.0
    regulariser: float = 0.3


@dataclass(frozen=True)
class TensionResult:
    """tensions (n,) N; force (3,) N and torque (3,) N·m displayed = Aᵀ t (about the grip
    centre, device frame); structure (n,6): A used; working (n,) int8: −1 at t_min, 0
    between, +1 at t_max; iterations and converged of the active-set solve."""

    tensions: np.ndarray
    force: np.ndarray
    torque: np.ndarray
    structure: np.ndarray
    working: np.ndarray
    iterations: int
    converged: bool

    @property
    def wrench(self) -> np.ndarray:
        """Displayed wrench (f, τ) (6,)."""
        return np.concatenate((self.force, self.torque))


def qp_matrices(
    structure: np.ndarray, force: np.ndarray, torque: np.ndarray, weights: TensionWeights
) -> tuple[np.ndarray, np.ndarray]:
    """(Q, c) of ½ tᵀQt − cᵀt for the wanted force and torque."""
    u, m = structure[:, :3], structure[:, 3:]
    q = weights.force * u @ u.T + weights.torque * m @ m.T
    q += weights.regulariser * np.eye(len(structure))
    c = weights.force * u @ np.asarray(force, float) + weights.torque * m @ np.asarray(
        torque, float
    )
    return q, c


def solve_tensions(
    structure: np.ndarray,
    force: np.ndarray,
    torque: np.ndarray,
    t_min: float,
    t_max: float,
    weights: TensionWeights | None = None,
    warm: TensionResult | None = None,
    max_iterations: int | None = None,
) -> TensionResult:
    """Solve the tension QP for A (n,6) and the wanted (f_d, τ_d); see the module docstring.

    ``warm``: the previous tick's result (solution and working set) to start from.
    ``max_iterations``: None = exact (to KKT); a small cap mimics the device's bounded
    solver (the result is then feasible but possibly not optimal: see ``converged``).
    """
    weights = weights or TensionWeights()
    if weights.regulariser <= 0.0 or weights.force < 0.0 or weights.torque < 0.0:
        raise DeviceError("tension weights: expected regulariser > 0 and force, torque >= 0")
    q, c = qp_matrices(structure, force, torque, weights)
    n = len(structure)
    lo, hi = np.full(n, float(t_min)), np.full(n, float(t_max))
    x0 = None if warm is None else warm.tensions
    w0 = None if warm is None else warm.working
    result = solve_box_qp(q, c, lo, hi, x0, w0, max_iterations)
    t = result.x
    shown = structure.T @ t  # one product, so the result is bit-for-bit Aᵀt
    return TensionResult(
        t, shown[:3], shown[3:], structure, result.working, result.iterations, result.converged
    )


class TensionDistributor:
    """Per-device tension solver that warm-starts from its previous solution, as the device
    does once per tick (or per physics step)."""

    def __init__(
        self,
        preset: DevicePreset,
        weights: TensionWeights | None = None,
        max_iterations: int | None = None,
    ) -> None:
        self.preset = preset
        self.weights = weights or TensionWeights()
        self.max_iterations = max_iterations
        self.last: TensionResult | None = None

    def display(
        self, pos: np.ndarray, q: np.ndarray, force: np.ndarray, torque: np.ndarray
    ) -> TensionResult:
        """Tensions and displayed wrench for the wanted (f, τ) with the grip at (pos, q)."""
        a = structure_matrix(self.preset, pos, q)
        p = self.preset
        self.last = solve_tensions(
            a, force, torque, p.t_min, p.t_max, self.weights, self.last, self.max_iterations
        )
        return self.last


def motor_volts(preset: DevicePreset, tensions: np.ndarray) -> np.ndarray:
    """Motor commands (n,) V: each tension clamped to [t_min, t_max] times its signed V/N."""
    if preset.volts_per_newton is None:
        raise DeviceError(f"{preset.name}: no volts_per_newton in this preset")
    return np.clip(tensions, preset.t_min, preset.t_max) * preset.volts_per_newton


def _max_along(a: np.ndarray, direction: np.ndarray, t_min: float, t_max: float) -> float:
    """max α s.t. Aᵀt = α·direction, t ∈ [t_min, t_max]ⁿ (0 when not even α = 0 is feasible)."""
    from scipy.optimize import linprog  # on use: importing scipy's costs a run ~0.3 s

    n = len(a)
    cost = np.zeros(n + 1)
    cost[-1] = -1.0
    a_eq = np.hstack((a.T, -direction[:, None]))
    bounds = [(t_min, t_max)] * n + [(0.0, None)]
    res = linprog(cost, A_eq=a_eq, b_eq=np.zeros(6), bounds=bounds, method="highs")
    return float(res.x[-1]) if res.status == 0 else 0.0


def capacity(
    preset: DevicePreset, pos: np.ndarray | None = None, q: np.ndarray | None = None
) -> dict[str, dict[str, float]]:
    """Largest pure force (N) and pure torque (N·m) along ±x, ±y, ±z (home by default).

    ``{"force": {"+x": …, "-x": …, …}, "torque": {…}}``: for each, max α such that some
    t ∈ [t_min, t_max]ⁿ gives Aᵀt = α·e exactly (the other five components zero).
    """
    pos = np.zeros(3) if pos is None else pos
    q = quat.IDENTITY if q is None else q
    a = structure_matrix(preset, pos, q)
    out: dict[str, dict[str, float]] = {"force": {}, "torque": {}}
    for block, offset in (("force", 0), ("torque", 3)):
        for axis, label in enumerate("xyz"):
            for sign, mark in ((1.0, "+"), (-1.0, "-")):
                direction = np.zeros(6)
                direction[offset + axis] = sign
                out[block][mark + label] = _max_along(a, direction, preset.t_min, preset.t_max)
    return out


def _cube_directions() -> np.ndarray:
    """The 26 unit vectors toward a cube's faces, edges and corners."""
    cube = np.array([d for d in itertools.product((-1.0, 0.0, 1.0), repeat=3) if any(d)])
    return cube / np.linalg.norm(cube, axis=1)[:, None]


def least_capacity(preset: DevicePreset) -> tuple[float, float]:
    """(force N, torque N·m) the device can display at home in every direction: the least
    of the largest pure force (torque) over the 26 cube directions."""
    a = structure_matrix(preset, np.zeros(3), quat.IDENTITY)
    found = []
    for offset in (0, 3):
        least = np.inf
        for d in _cube_directions():
            direction = np.zeros(6)
            direction[offset : offset + 3] = d
            least = min(least, _max_along(a, direction, preset.t_min, preset.t_max))
        found.append(float(least))
    return found[0], found[1]
