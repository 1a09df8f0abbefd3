"""What the user's hand feels: the device-side chain of the reference implementation.

requested = −(wrench the coupling or the pointer's contacts put on the doll);
then an optional one-pole low-pass y_k = a·y_{k−1} + (1 − a)·x_k, then a clamp of
the force and torque norms to the device's maximum (direction kept).  Both the
requested (unclamped) and the displayed wrench are recorded.
"""

from __future__ import annotations

import numpy as np


def clamp_norm(v: np.ndarray, limit: float) -> np.ndarray:
    """v scaled down to norm ``limit`` if longer."""
    n = float(np.linalg.norm(v))
    return v * (limit / n) if n > limit else v


class HapticChain:
    """Low-pass and clamp, keeping the filter state between steps."""

    def __init__(self, max_force: float, max_torque: float, lowpass: float) -> None:
        self.max_force = max_force
        self.max_torque = max_torque
        self.lowpass = lowpass
        self.filtered = np.zeros(6)

    def display(self, force: np.ndarray, torque: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(force, torque) displayed for the requested wrench on the hand."""
        a = self.lowpass
        self.filtered = a * self.filtered + (1.0 - a) * np.concatenate((force, torque))
        return clamp_norm(self.filtered[:3], self.max_force), clamp_norm(
            self.filtered[3:], self.max_torque
        )
