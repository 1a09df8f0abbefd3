"""The paper's experiment (digest §5.1, rotational form): its constants and the exact
discrete recursion of the three-element row, written out independently of the solver."""

from __future__ import annotations

import numpy as np

KF, DF, DD, INERTIA, TAU = 1.0, 10.0, 100.0, 0.1, 1.0
T_LOAD, T_END = 2.0, 6.0


def recursion(h: float) -> np.ndarray:
    """Joint angle after every step (digest's recursion, one axis; torque TAU until T_LOAD)."""
    s = KF * h + DF
    c = (DD + DF + KF * h) / (DD * s)
    d = KF / s
    dq = (DD + DF) / (DD + DF + KF * h)
    dw = DD * h / (DD + DF + KF * h)
    theta = omega = q = 0.0
    out = []
    for k in range(round(T_END / h)):
        tau = TAU if k < round(T_LOAD / h) else 0.0
        omega_free = omega + h * tau / INERTIA
        lam = -(omega_free + d * q) / (h / INERTIA + c)
        omega = omega_free + h / INERTIA * lam
        q = dq * q + dw * omega
        theta += h * omega
        out.append(theta)
    return np.array(out)
