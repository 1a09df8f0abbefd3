"""Compliant rows: the three-element (plastic) row and the Voigt (spring-damper) row.

A compliant row is an equality row of the modified LCP

    w[t+1] + C·λ + β = 0,

where w[t+1] = J v[t+1] is the row velocity after the step, λ the row force
(N or N·m), C the compliance on the diagonal and β the bias.

Voigt row (spring K, damper D, deflection e measured now):
    λ = −K (e + h w) − D w      (backward Euler: the spring sees e[t+1] = e + h w)
  ⇒ w + λ/(D + K h) + K e/(D + K h) = 0,   C = 1/(D + K h),  β = K e/(D + K h).

Three-element row (digest §4.4).  Voigt element (K_f ∥ D_f, deflection q_sf)
in series with the damper D_d:
    λ = −K_f q_sf[t+1] − D_f w_sf = −D_d w_sd,  w = w_sf + w_sd,
    q_sf[t+1] = q_sf[t] + h w_sf.
Eliminating w_sf, w_sd:
    w[t+1] = −C λ − D q_sf[t],
        C = (D_d + D_f + K_f h) / (D_d (K_f h + D_f)),  D = K_f / (K_f h + D_f),
    q_sf[t+1] = Dq q_sf[t] + Dw w[t+1],
        Dq = (D_d + D_f) / (D_d + D_f + K_f h),  Dw = D_d h / (D_d + D_f + K_f h).
As D_d → ∞ these tend to the Voigt row (C → 1/(K_f h + D_f), Dq → 1, Dw → h).
Units (angular rows): K N·m/rad, D N·m·s/rad, C rad/(N·m·s), β rad/s.
"""

from __future__ import annotations

import numpy as np


def voigt_row(kf: np.ndarray, df: np.ndarray, e: np.ndarray, h: float) -> tuple:
    """Compliance and bias of Voigt rows with deflection ``e``: (C, β)."""
    s = df + kf * h
    return 1.0 / s, kf * e / s


def three_element_row(
    kf: np.ndarray, df: np.ndarray, dd: np.ndarray, q_sf: np.ndarray, h: float
) -> tuple:
    """Compliance and bias of three-element rows: (C, β = D·q_sf[t])."""
    s = kf * h + df
    return (dd + df + kf * h) / (dd * s), kf / s * q_sf


def three_element_update(
    kf: np.ndarray, df: np.ndarray, dd: np.ndarray, q_sf: np.ndarray, w: np.ndarray, h: float
) -> np.ndarray:
    """q_sf[t+1] from q_sf[t] and the solved row velocity w[t+1]."""
    t = dd + df + kf * h
    return ((dd + df) * q_sf + dd * h * w) / t
