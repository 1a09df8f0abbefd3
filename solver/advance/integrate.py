"""Semi-implicit Euler in maximal coordinates (digest §4.3), momentum form.

    v_free = v + h (g + F/m),            ω_free = ω + h I_w⁻¹ τ
    v[t+1] = v_free + h M⁻¹ Jᵀ λ          (the solver's result)
    x[t+1] = x + h v[t+1],               q[t+1] = normalise(exp(h ω[t+1]) ⊗ q)

Gyroscopic term: the angular momentum L = I_w(q) ω[t+1] (after the constraint
impulses) is what the body keeps; the rotation over the step uses the implicit
midpoint rate ω_m = I_w(q_m)⁻¹ L with q_m = exp(½hω_m) ⊗ q (a few fixed-point
passes), and the next step starts from ω = I_w(q[t+1])⁻¹ L.  Torque-free this
conserves L exactly and, being symmetric in time, does not pump energy into a
spinning asymmetric body (rotating by the start-of-step rate, then carrying L,
raises E by ~½h²(Ω×Π)ᵀI⁻¹(Ω×Π) every step).  For an isotropic inertia ω_m = ω,
so scalar recursions are unchanged.
"""

from __future__ import annotations

import numpy as np

from solver import quat
from solver.model import Model
from solver.state import State, StepInput


def free_velocity(
    model: Model, state: State, inp: StepInput, inv_inertia_world: np.ndarray
) -> np.ndarray:
    """(nb,6) velocities after external forces and gravity, before constraints."""
    h = model.options.h
    movable = model.body_inv_mass > 0.0
    acc = np.where(movable[:, None], model.options.gravity, 0.0)
    if inp.body_force is not None:
        acc = acc + inp.body_force * model.body_inv_mass[:, None]
    omega = state.body_omega
    if inp.body_torque is not None:
        omega = omega + h * np.einsum("nij,nj->ni", inv_inertia_world, inp.body_torque)
    return np.concatenate((state.body_vel + h * acc, omega), axis=1)


def integrate_pose(
    model: Model, state: State, vel: np.ndarray, body_rot: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(pos, quat, omega) at t+1 from the solved velocities (nb,6)."""
    h = model.options.h
    pos = state.body_pos + h * vel[:, :3]
    inertia_w = body_rot @ model.body_inertia @ np.swapaxes(body_rot, 1, 2)
    momentum = np.einsum("nij,nj->ni", inertia_w, vel[:, 3:])
    rate = vel[:, 3:]
    for _ in range(MIDPOINT_PASSES):
        mid = quat.mul(quat.exp(0.5 * h * rate), state.body_quat)
        rate = _omega_from_momentum(model, mid, momentum)
    q = quat.normalize(quat.mul(quat.exp(h * rate), state.body_quat))
    return pos, q, _omega_from_momentum(model, q, momentum)


MIDPOINT_PASSES = 4


def _omega_from_momentum(model: Model, q: np.ndarray, momentum: np.ndarray) -> np.ndarray:
    """ω = I_w(q)⁻¹ L, (nb,3); zero for immovable bodies."""
    rot = quat.matrix(q)
    inv = rot @ model.body_inv_inertia @ np.swapaxes(rot, 1, 2)
    return np.einsum("nij,nj->ni", inv, momentum)
