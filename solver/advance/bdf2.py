"""Second-order steps: BDF2, linearised at the predicted end of the step.

The paper's step (digest §4.3) is backward Euler on the joints' springs and dampers and
semi-implicit Euler on the bodies: first order, and its implicit spring adds K·h of
numerical damping to every joint.  ``integrator: bdf2`` takes the two-step backward
differentiation formula instead, second order and L-stable (its large-step limit damps
the fastest modes to zero instead of flipping them, as the trapezoidal rule would).
With r = h/h_prev (1 at a constant step) and c = r²/(1 + 2r), γ = h(1 + r)/(1 + 2r):

    x[t+1] = x̂ + γ v[t+1],      x̂ = x + c (x − x_prev)
    p[t+1] = p̂ + γ F[t+1],      p̂ = p + c (p − p_prev)     (p: momentum, F: all forces)

(r = 1: x̂ = (4x − x_prev)/3, γ = 2h/3).  Every quantity is the stage's, so a BDF2 step is
the paper's step over γ from (x̂, p̂), with all forces at t+1: the springs' deflection
e[t+1], the rows' directions J(x[t+1]), the world inertia I_w(q[t+1]).  Linearised at
x̂ as the paper's step is, J and I_w would be O(h) off and the step first order again; so
the rows are linearised at the predicted end pose

    x̃ = x̂ + γ ṽ,   ṽ = v      (x̃ − x[t+1] = γ (v − v[t+1]) = O(h²))

and the unknown is δv = v[t+1] − ṽ: x[t+1] = x̃ + γ δv, e[t+1] = e(x̃) + γ J δv.  J and I_w
at x̃ are O(h²) off, which moves v[t+1] by γ·O(h²): a local error of O(h³), as BDF2's own.
(Extrapolating ṽ = v + r (v − v_prev) is as accurate, and measured slightly worse, but it
throws the guess far off at large steps: the doll released from a bend then tore a joint
apart at 200 ms.)  Rotations
go the same way on the group: q̂ = exp(c·log(q q_prev⁻¹)) ⊗ q, q̃ = exp(γ ω̃) ⊗ q̂,
q[t+1] = exp(γ δω) ⊗ q̃, with the angular momentum L = I_w ω in the world frame (no
gyroscopic term there): L̂ = L + c (L − L_prev), the stage's start rate ω̂ = I_w(q̃)⁻¹ L̂.
A row whose law involves its velocity w = J v = J δv + J ṽ (a damper, friction, the
three-element row) adds its share of J ṽ to its bias (solver.rows.shift); a row on
position only (an anchor, a contact's normal, a limit) does not.  The three-element
row's elastic state is extrapolated the same way: q̂_sf = q_sf + c (q_sf − q_sf_prev).

The State keeps the previous step's pose, velocities and q_sf (``State.prev_*``), the
step they came from (``prev_h``) and a fingerprint of the state they lead to
(``prev_mark``, ``mark``).  A state whose arrays were changed after its step (a
replaced pose, a new initial state) no longer matches its fingerprint, and its next
step is a backward Euler step (BDF1: x̂ = x, γ = h, ṽ = v), as is the first step of a
run, one after a step ratio r above R_MAX, and a joint's q_sf across a yield switch.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import partial

import numpy as np

from solver import quat
from solver.advance.bdf2_kernel import R_MAX, load_mark, mark
from solver.compiled.layout import Coupling
from solver.model import Model, kept_with
from solver.rows.grip import coupling_vector
from solver.rows.grip_kernel import MODE_GRIP, MODE_NONE, MODE_TOUCH
from solver.state import State, StepInput


@dataclass(frozen=True)
class Prediction:
    """A BDF2 step's stage.

    gamma (s): the stage's length; pos (nb,3), quat (nb,4): the predicted end pose x̃, q̃;
    start (nb,6): the stage's start velocities, v̂ − ṽ and ω̂ − ω̃; shift (nb,6): ṽ, ω̃;
    q_sf (nj,3): q̂_sf.
    """

    gamma: float
    pos: np.ndarray
    quat: np.ndarray
    start: np.ndarray
    shift: np.ndarray
    q_sf: np.ndarray


def load(inp: StepInput, nb: int) -> float:
    """The fingerprint of a step's input (solver.advance.bdf2_kernel.load_mark): its loads,
    the pointer's mode (none, touching, gripping), the gripped body and the coupling."""
    ptr, cpl = inp.pointer, inp.coupling
    mode, body, cvec = MODE_NONE, 0, np.zeros(Coupling.SIZE)
    if ptr is not None and (cpl is not None or ptr.radius > 0.0):
        mode = MODE_TOUCH
        if cpl is not None:
            mode, body, cvec = MODE_GRIP, cpl.body, coupling_vector(cpl)
    force = np.zeros((nb, 3)) if inp.body_force is None else np.asarray(inp.body_force, float)
    torque = np.zeros((nb, 3)) if inp.body_torque is None else np.asarray(inp.body_torque, float)
    has = (inp.body_force is not None, inp.body_torque is not None)
    return load_mark(np.ascontiguousarray(force), np.ascontiguousarray(torque), *has, mode, body,
                     cvec)  # fmt: skip


def ratio(state: State, h: float, load: float) -> float:
    """h/h_prev if the state carries a usable history for a step h whose input has the
    fingerprint ``load``, else 0."""
    if state.prev_h <= 0.0 or len(state.prev_pos) != len(state.body_pos):
        return 0.0
    if load != state.prev_load:
        return 0.0
    r = h / state.prev_h
    if r > R_MAX:
        return 0.0
    now = mark(state.body_pos, state.body_quat, state.body_vel, state.body_omega,
               state.joint_q_sf)  # fmt: skip
    return r if now == state.prev_mark else 0.0


def restarts(model: Model, r: float) -> bool:
    """True when a BDF2 step at step ratio r has no usable history (r = 0) and is taken in
    ``RESTART``'s parts (not by a model that never subdivides: max_substeps = 1, as every
    part's)."""
    return r == 0.0 and model.options.max_substeps > 1


def stage_length(h: float, r: float) -> float:
    """γ = h(1 + r)/(1 + 2r); h for r = 0 (backward Euler)."""
    return h * (1.0 + r) / (1.0 + 2.0 * r)


def angular_momentum(model: Model, q: np.ndarray, omega: np.ndarray) -> np.ndarray:
    """Each body's angular momentum about its centre, I_w ω (N·m·s, world), at orientations q."""
    rot = quat.matrix(q)
    inertia_w = rot @ model.body_inertia @ np.swapaxes(rot, 1, 2)
    return np.einsum("nij,nj->ni", inertia_w, omega)


def predict(model: Model, state: State, r: float) -> Prediction:
    """The stage of a step h = model.options.h from ``state`` at step ratio r: BDF2 for
    r > 0 (``ratio``), backward Euler linearised at x + h v for r = 0 (the history unread:
    the state stands in for its previous step, every difference zero)."""
    h = model.options.h
    c = r * r / (1.0 + 2.0 * r)
    gamma = stage_length(h, r)
    s = state
    p_pos, p_quat, p_vel, p_omega, p_q_sf = (
        (s.prev_pos, s.prev_quat, s.prev_vel, s.prev_omega, s.prev_q_sf) if r > 0.0
        else (s.body_pos, s.body_quat, s.body_vel, s.body_omega, s.joint_q_sf)
    )  # fmt: skip
    pos_hat = state.body_pos + c * (state.body_pos - p_pos)
    turn = quat.log(quat.mul(state.body_quat, quat.conj(p_quat)))
    q_hat = quat.normalize(quat.mul(quat.exp(c * turn), state.body_quat))
    vel_hat = state.body_vel + c * (state.body_vel - p_vel)
    mom = angular_momentum(model, state.body_quat, state.body_omega)
    mom_hat = mom + c * (mom - angular_momentum(model, p_quat, p_omega))
    v_tilde, w_tilde = state.body_vel, state.body_omega
    pos = pos_hat + gamma * v_tilde
    q = quat.normalize(quat.mul(quat.exp(gamma * w_tilde), q_hat))
    rot = quat.matrix(q)
    inv_w = rot @ model.body_inv_inertia @ np.swapaxes(rot, 1, 2)
    w_hat = np.einsum("nij,nj->ni", inv_w, mom_hat)
    start = np.concatenate((vel_hat - v_tilde, w_hat - w_tilde), axis=1)
    q_sf = state.joint_q_sf + c * (state.joint_q_sf - p_q_sf)
    return Prediction(gamma, pos, q, start, np.concatenate((v_tilde, w_tilde), axis=1), q_sf)


def history(state: State, h: float, load: float, new: dict) -> dict:
    """The history fields of the State after a step h with an input of fingerprint
    ``load`` from ``state``: ``new`` holds the new body_pos, body_quat, body_vel,
    body_omega, joint_q_sf and joint_yielded; a joint that switched between flowing and
    elastic keeps no q_sf history."""
    kept = state.joint_yielded == new["joint_yielded"]
    prev_q_sf = np.where(kept[:, None], state.joint_q_sf, new["joint_q_sf"])
    fingerprint = mark(
        new["body_pos"], new["body_quat"], new["body_vel"], new["body_omega"], new["joint_q_sf"]
    )
    return dict(
        prev_pos=state.body_pos,
        prev_quat=state.body_quat,
        prev_vel=state.body_vel,
        prev_omega=state.body_omega,
        prev_q_sf=prev_q_sf,
        prev_h=h,
        prev_mark=fingerprint,
        prev_load=load,
    )


_STAGE_MODELS: dict[tuple[int, float], Model] = {}


def stage_model(model: Model, gamma: float) -> Model:
    """``model`` for a stage of length γ: h = γ, and the yield filter's time constant
    scaled by γ/h so that its per-step weight h/(T + h) is the real step's."""
    o = model.options
    build = partial(model.with_options, h=gamma,
                    yield_filter_time=o.yield_filter_time * gamma / o.h)  # fmt: skip
    return kept_with(model, _STAGE_MODELS, build, (id(model), gamma))


def stage_state(state: State, pred: Prediction) -> State:
    """The state the stage starts from: the predicted end pose, the start velocities
    δv's stage begins with, and q̂_sf."""
    return replace(
        state, body_pos=pred.pos, body_quat=pred.quat, body_vel=pred.start[:, :3],
        body_omega=pred.start[:, 3:], joint_q_sf=pred.q_sf,
    )  # fmt: skip


def integrate_stage(
    model: Model, pred: Prediction, vel: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(pos, quat, velocities (nb,6), ω) at t+1 from the stage's solved δv (nb,6): x̃ + γ δv,
    exp(γ δω) ⊗ q̃; v = δv + ṽ; the body keeps the angular momentum the solve gave it,
    L = I_w(q̃) ω, so ω[t+1] = I_w(q[t+1])⁻¹ L (a torque-free body conserves L exactly)."""
    g = pred.gamma
    pos = pred.pos + g * vel[:, :3]
    q = quat.normalize(quat.mul(quat.exp(g * vel[:, 3:]), pred.quat))
    true = vel + pred.shift
    mom = angular_momentum(model, pred.quat, true[:, 3:])
    rot = quat.matrix(q)
    inv_w = rot @ model.body_inv_inertia @ np.swapaxes(rot, 1, 2)
    return pos, q, true, np.einsum("nij,nj->ni", inv_w, mom)
