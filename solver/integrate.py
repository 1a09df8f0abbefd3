"""Semi-implicit Euler in maximal coordinates (digest §4.3), momentum form.

    v_free = v + h (g + F/m),            ω_free = ω + h I_w⁻¹ τ
    v[t+1] = v_free + h M⁻¹ Jᵀ λ          (the solver's result)
    x[t+1] = x + h v[t+1],               q[t+1] = normalise(exp(h ω[t+1]) ⊗ q)

Gyroscopic term: rather than the explicit −I⁻¹(ω × Iω) (which pumps energy into
a fast-spinning asymmetric body), the angular momentum L = I_w(q) ω[t+1] is
carried through the rotation: the next step starts from
ω = I_w(q[t+1])⁻¹ L.  Torque-free, this conserves L exactly and keeps the
kinetic energy bounded by |L|²/(2 I_min); for an isotropic inertia it is the
identity, so scalar recursions are unchanged.
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
    q = quat.normalize(quat.mul(quat.exp(h * vel[:, 3:]), state.body_quat))
    # Carry angular momentum through the rotation (gyroscopic term).
    inertia_w = body_rot @ model.body_inertia @ np.swapaxes(body_rot, 1, 2)
    momentum = np.einsum("nij,nj->ni", inertia_w, vel[:, 3:])
    rot_new = quat.matrix(q)
    inv_new = rot_new @ model.body_inv_inertia @ np.swapaxes(rot_new, 1, 2)
    omega = np.einsum("nij,nj->ni", inv_new, momentum)
    return pos, q, omega
