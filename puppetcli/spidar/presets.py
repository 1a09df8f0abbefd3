"""SPIDAR-G device presets: where the strings leave the frame and where they hold the grip.

Frames (right-handed, metres, the puppet world's Y-up convention):

- **device frame**: x right, y up, z toward the user; origin = frame centre = grip home.
- **grip frame**: fixed to the grip, origin at its centre; it coincides with the device
  frame at home (p = 0, R = I), where the device is calibrated.

String i leaves the frame at ``motor_pos[i]`` (the pulley exit m_i, device frame) and is
tied to the grip at ``grip_attach[i]`` (a_i, grip frame).  The encoder of motor i counts
string length in steps of ``metres_per_count[i]`` (κ_i); its sign encodes the winding
direction (a positive count change lengthens the string when κ_i > 0).  Tensions are
bounded to [t_min, t_max] N; ``volts_per_newton[i]`` (signed like κ_i) turns a tension
into the motor command.

The built-in tables follow Springhead's ``HISpidarGDesc::Init(type)``
(``core/src/HumanInterface/HISpidar.cpp``) and, for ``HISpidarG6X``, the 2010
``src/HIS/HISpidarG6X.cpp``; see docs/spidar.md for the tables and provenance.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from puppetcli.spidar.errors import DeviceError
from solver import quat

__all__ = ["DevicePreset", "preset", "preset_names"]


def _frozen_array(value: object, shape: tuple[int, ...], what: str) -> np.ndarray:
    """A read-only float copy of ``value`` with the given shape (−1 = any length ≥ 1)."""
    array = np.array(value, dtype=float)
    ok = array.ndim == len(shape)
    ok = ok and all(s in (-1, n) for s, n in zip(shape, array.shape, strict=True))
    if not ok or array.size == 0 or not np.all(np.isfinite(array)):
        raise DeviceError(f"{what}: expected finite numbers of shape {shape}, got {array.shape}")
    array.setflags(write=False)
    return array


@dataclass(frozen=True, eq=False)
class DevicePreset:
    """One string-driven grip device (immutable).

    name: preset name.  motor_pos (n,3) m: string exits m_i, device frame.
    grip_attach (n,3) m: attachment points a_i, grip frame.  metres_per_count (n,) m:
    signed string length per encoder count κ_i.  t_min, t_max (N): tension bounds.
    volts_per_newton (n,) V/N, signed, or None when unknown.  source: provenance text.
    """

    name: str
    motor_pos: np.ndarray
    grip_attach: np.ndarray
    metres_per_count: np.ndarray
    t_min: float
    t_max: float
    volts_per_newton: np.ndarray | None = None
    source: str = ""

    def __post_init__(self) -> None:
        motors = _frozen_array(self.motor_pos, (-1, 3), f"{self.name}: motor_pos")
        n = len(motors)
        set_field = object.__setattr__  # frozen: normalise the arrays once, here
        set_field(self, "motor_pos", motors)
        set_field(self, "grip_attach", _frozen_array(self.grip_attach, (n, 3), "grip_attach"))
        kappa = _frozen_array(self.metres_per_count, (n,), f"{self.name}: metres_per_count")
        if np.any(kappa == 0.0):
            raise DeviceError(f"{self.name}: metres_per_count: expected non-zero, got 0")
        set_field(self, "metres_per_count", kappa)
        if self.volts_per_newton is not None:
            vpn = _frozen_array(self.volts_per_newton, (n,), f"{self.name}: volts_per_newton")
            set_field(self, "volts_per_newton", vpn)
        if n < 7:
            raise DeviceError(f"{self.name}: expected at least 7 strings for 6 DOF, got {n}")
        if not (0.0 <= self.t_min < self.t_max and math.isfinite(self.t_max)):
            raise DeviceError(
                f"{self.name}: expected 0 <= t_min < t_max, got [{self.t_min}, {self.t_max}]"
            )

    @property
    def n_strings(self) -> int:
        """Number of strings n."""
        return len(self.motor_pos)

    @cached_property
    def home_lengths(self) -> np.ndarray:
        """String lengths at home l_i,home = |m_i − a_i| (n,), m."""
        return np.linalg.norm(self.motor_pos - self.grip_attach, axis=1)

    @cached_property
    def frame_planes(self) -> np.ndarray:
        """Half-spaces (k,4) of the convex hull of the string exits: n·x + d ≤ 0 inside."""
        from scipy.spatial import ConvexHull  # on use: importing scipy's costs a run ~0.3 s

        return ConvexHull(self.motor_pos).equations


# --- built-in presets -------------------------------------------------------------------------


def _rot_y(points: np.ndarray, degrees: float) -> np.ndarray:
    """Points rotated about the device y axis (right-handed) by ``degrees``."""
    q = quat.exp(np.array([0.0, math.radians(degrees), 0.0]))
    rotated = quat.rotate(q, np.asarray(points, dtype=float))
    return np.where(np.abs(rotated) < 1e-15, 0.0, rotated)  # exact zeros stay zeros


def _signed(value: float, n: int, flipped: tuple[int, ...]) -> np.ndarray:
    """``value`` for n motors with the sign flipped on the listed ones."""
    out = np.full(n, value)
    out[list(flipped)] *= -1.0
    return out


# Corner sign patterns (x, y, z) of the string exits and grip-point axes of each layout.
_G6X3R_MOTORS = [(-1, -1, 1), (1, -1, 1), (1, -1, -1), (-1, -1, -1)]
_G6X3R_MOTORS += [(-1, 1, 1), (1, 1, 1), (1, 1, -1), (-1, 1, -1)]
_G6X3R_GRIP = [(-1, 0, 0), (1, 0, 0), (0, -1, 0), (0, -1, 0)]
_G6X3R_GRIP += [(-1, 0, 0), (1, 0, 0), (0, 1, 0), (0, 1, 0)]
_G6X3L_MOTORS = [(1, 1, -1), (1, 1, 1), (-1, 1, 1), (-1, 1, -1)]
_G6X3L_MOTORS += [(1, -1, -1), (1, -1, 1), (-1, -1, 1), (-1, -1, -1)]
_G6X3L_GRIP = [(0, 0, -1), (0, 0, 1), (0, 1, 0), (0, 1, 0)]
_G6X3L_GRIP += [(0, 0, -1), (0, 0, 1), (0, -1, 0), (0, -1, 0)]


def _spidar_g6x3(left: bool) -> DevicePreset:
    """SPIDAR-G6X3 (aluminium frame, the 2010 unit): box 0.12 × 0.152 × 0.12 m turned −45°
    about y, 45 mm grip; κ = 1.66555e-5 m, sign flipped on motors 2–5 (both hands)."""
    half = np.array([0.12, 0.152, 0.12]) / 2.0
    grip = 0.045 / 2.0
    motors = np.array(_G6X3L_MOTORS if left else _G6X3R_MOTORS) * half
    attach = np.array(_G6X3L_GRIP if left else _G6X3R_GRIP) * grip
    return DevicePreset(
        name="SpidarG6X3L" if left else "SpidarG6X3R",
        motor_pos=_rot_y(motors, -45.0),
        grip_attach=_rot_y(attach, -45.0),
        metres_per_count=_signed(1.66555e-5, 8, (2, 3, 4, 5)),
        t_min=0.3,
        t_max=20.0,
        volts_per_newton=np.full(8, 0.365296803653),
        source="Springhead HISpidar.cpp, HISpidarGDesc::Init('SpidarG6X3L'/'SpidarG6X3R')",
    )


_G6X4_MOTORS = [(1, -1, -1), (1, -1, 1), (-1, -1, 1), (-1, -1, -1)]
_G6X4_MOTORS += [(1, 1, -1), (1, 1, 1), (-1, 1, 1), (-1, 1, -1)]
_G6X4_GRIP = [(0, -1, 0), (1, 0, 0), (-1, 0, 0), (0, -1, 0)]
_G6X4_GRIP += [(0, 1, 0), (1, 0, 0), (-1, 0, 0), (0, 1, 0)]


def _spidar_g6x4(left: bool) -> DevicePreset:
    """SPIDAR-G6X4 (MDF frame): box 0.138 × 0.190 × 0.138 m, 45 mm grip, κ = 3.485e-5 m.

    Springhead builds the left and right units identically (its ``bLeft`` is unused): the
    layout is symmetric under x → −x, so the mirror image of the unit is the same unit
    with motors relabelled (0↔3, 1↔2, 4↔7, 5↔6).
    """
    half = np.array([0.138, 0.190, 0.138]) / 2.0
    return DevicePreset(
        name="SpidarG6X4L" if left else "SpidarG6X4R",
        motor_pos=np.array(_G6X4_MOTORS) * half,
        grip_attach=np.array(_G6X4_GRIP) * (0.045 / 2.0),
        metres_per_count=_signed(3.485e-5, 8, (0, 1, 6, 7)),
        t_min=0.2,
        t_max=20.0,
        volts_per_newton=_signed(0.08, 8, (2, 3, 4, 5)),
        source="Springhead HISpidar.cpp, HISpidarGDesc::Init('SpidarG6X4L'/'SpidarG6X4R')",
    )


_G6X_MOTORS = [(-1, -1, 1), (-1, -1, -1), (1, -1, -1), (1, -1, 1)]
_G6X_MOTORS += [(-1, 1, 1), (-1, 1, -1), (1, 1, -1), (1, 1, 1)]
_G6X_GRIP = [(0, -1, 0), (-1, 0, 0), (1, 0, 0), (0, -1, 0)]
_G6X_GRIP += [(0, 1, 0), (-1, 0, 0), (1, 0, 0), (0, 1, 0)]


def _hispidar_g6x() -> DevicePreset:
    """HISpidarG6X (2010 Springhead): box 0.129 × 0.129 × 0.137 m, 40 mm grip, measured
    κ = 2.924062107079e-5 m with the sign flipped on motors 0, 2, 5, 7, tensions 1–20 N.
    The source's "PZ" is −0.137/2, which the corner table below already folds in."""
    half = np.array([0.129, 0.129, -0.137]) / 2.0
    return DevicePreset(
        name="HISpidarG6X",
        motor_pos=np.array(_G6X_MOTORS) * half,
        grip_attach=np.array(_G6X_GRIP) * (0.04 / 2.0),
        metres_per_count=_signed(2.924062107079e-5, 8, (0, 2, 5, 7)),
        t_min=1.0,
        t_max=20.0,
        volts_per_newton=np.full(8, 0.12),
        source="Springhead (2010) src/HIS/HISpidarG6X.cpp, HISpidarG6X::Init",
    )


_BUILDERS: dict[str, Callable[[], DevicePreset]] = {
    "SpidarG6X3R": lambda: _spidar_g6x3(left=False),
    "SpidarG6X3L": lambda: _spidar_g6x3(left=True),
    "SpidarG6X4R": lambda: _spidar_g6x4(left=False),
    "SpidarG6X4L": lambda: _spidar_g6x4(left=True),
    "HISpidarG6X": _hispidar_g6x,
}


def preset_names() -> tuple[str, ...]:
    """Names of the built-in presets."""
    return tuple(_BUILDERS)


def preset(name: str) -> DevicePreset:
    """The built-in preset ``name`` (case-insensitive, as Springhead's ``stricmp``).

    Raises ``DeviceError`` with a did-you-mean hint for an unknown name.
    """
    by_lower = {known.lower(): known for known in _BUILDERS}
    known = by_lower.get(name.lower())
    if known is None:
        close = difflib.get_close_matches(name.lower(), sorted(by_lower), n=1)
        hint = f" (did you mean '{by_lower[close[0]]}'?)" if close else ""
        names = ", ".join(_BUILDERS)
        raise DeviceError(f"unknown device preset '{name}'{hint}; known presets: {names}")
    return _BUILDERS[known]()
