"""What the user's hand feels: the device-side chain of the reference implementation.

requested = −(wrench the coupling or the pointer's contacts put on the doll);
then an optional one-pole low-pass y_k = a·y_{k−1} + (1 − a)·x_k, then a clamp of
the force and torque norms to the device's maximum (direction kept).  Both the
requested (unclamped) and the displayed wrench are recorded.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

Vec = tuple[float, float, float]


def norm3(v: Vec) -> float:
    """|v|, computed as numpy computes each row's norm in ``display_many``."""
    return math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])


def clamp_norm(v: Vec, limit: float) -> Vec:
    """v scaled down to norm ``limit`` if longer."""
    n = norm3(v)
    if n <= limit:
        return v
    k = limit / n
    return (v[0] * k, v[1] * k, v[2] * k)


def row_norms(v: np.ndarray) -> np.ndarray:
    """|v| of each row of v (n, 3): ``norm3`` of each, the same operations."""
    return np.sqrt(v[:, 0] * v[:, 0] + v[:, 1] * v[:, 1] + v[:, 2] * v[:, 2])


def clamp_rows(v: np.ndarray, limit: float) -> None:
    """``clamp_norm`` of each row of v (n, 3), in place."""
    n = row_norms(v)
    over = n > limit
    v[over] *= (limit / n[over])[:, None]


class HapticChain:
    """Low-pass and clamp, keeping the filter state between steps.  One wrench a step, in
    Python floats (a few µs; numpy's per-call overhead would be most of a step's Python)."""

    def __init__(self, max_force: float, max_torque: float, lowpass: float) -> None:
        self.max_force = max_force
        self.max_torque = max_torque
        self.lowpass = lowpass
        self.filtered = (0.0,) * 6

    def display(self, force, torque) -> tuple[Vec, Vec]:
        """(force, torque) displayed for the requested wrench on the hand (each any
        sequence of three floats)."""
        self.filtered = y = _low_pass(self.lowpass, self.filtered, (*force, *torque))
        return clamp_norm(y[:3], self.max_force), clamp_norm(y[3:], self.max_torque)

    def display_many(self, requested: np.ndarray) -> np.ndarray:
        """``display`` of each row of ``requested`` (n, 6: force, torque) in turn: the
        displayed (n, 6), the same floats as row by row, and the filter as after the last."""
        y = np.array(self.filtered, dtype=float)
        shown = np.empty((len(requested), 6))
        _low_pass_rows(self.lowpass, y, np.asarray(requested, dtype=float), shown)
        self.filtered = tuple(y.tolist())
        clamp_rows(shown[:, :3], self.max_force)
        clamp_rows(shown[:, 3:], self.max_torque)
        return shown


@njit(cache=True)
def _low_pass_rows(a: float, y: np.ndarray, x: np.ndarray, out: np.ndarray) -> None:
    """``_low_pass`` over the rows of x (n, 6) into out, from and updating y (6,): the same
    operations in the same order (compiled: one Python call for a batch of steps)."""
    b = 1.0 - a
    for k in range(x.shape[0]):
        for j in range(6):
            y[j] = a * y[j] + b * x[k, j]
            out[k, j] = y[j]


def _low_pass(a: float, y: tuple, x) -> tuple:
    """One step of the one-pole low-pass on six floats: a·y + (1 − a)·x."""
    b = 1.0 - a
    return (
        a * y[0] + b * x[0], a * y[1] + b * x[1], a * y[2] + b * x[2],
        a * y[3] + b * x[3], a * y[4] + b * x[4], a * y[5] + b * x[5],
    )  # fmt: skip
