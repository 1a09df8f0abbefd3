"""Compiled BDF2 stage (solver.advance.bdf2's twin): the state's fingerprint, the
prediction, the stage's integration and the history the new state keeps."""

from __future__ import annotations

from solver.compiled.layout import Opt
from solver.jit import kernel
from solver.kin_kernel import (
    add,
    matvec,
    put,
    qconj,
    qexp,
    qlog,
    qmatrix,
    qmul,
    qnormalize,
    quat_at,
    scale,
    sub,
    tmatvec,
    vec,
)

R_MAX = 2.0
"""Largest step ratio h/h_prev taken as BDF2 (variable-step BDF2 is zero-stable below
1 + √2); a larger one (the first step after substeps) restarts with backward Euler."""


RESTART = (4, 4, 2)
"""A restart's parts (h/4, h/4, h/2: solver.advance.substep.run_parts): backward Euler over
h/4, then BDF2 at r = 1 and r = 2; the next step goes on at r = 2.  A step without a usable
history (the first of a run, the first after its input jumped) is backward Euler, whose
local error where the acceleration jumps by Δa, ~½h²·Δa, stays in every later state; over
h/4 it is 1/16 of that (tests/solver/test_bdf2.py measures what it leaves)."""


@kernel(error_model="numpy")
def _weigh(a, k, total):
    """Σ (k + 1) a_k over a 2-D array's entries in order, from index k: (total, next k)."""
    for i in range(a.shape[0]):
        for j in range(a.shape[1]):
            k += 1
            total += k * a[i, j]
    return total, k


@kernel(error_model="numpy")
def mark(pos, q, vel, omega, q_sf):
    """A fingerprint of a state's arrays: Σ_k (k + 1)·a_k over them all in order, which a
    changed entry, two different entries swapped or a uniform shift changes (the numpy step
    calls this one too, so a state either step made matches in the other)."""
    total, k = _weigh(pos, 0, 0.0)
    total, k = _weigh(q, k, total)
    total, k = _weigh(vel, k, total)
    total, k = _weigh(omega, k, total)
    total, k = _weigh(q_sf, k, total)
    return total


@kernel(error_model="numpy")
def load_mark(force, torque, has_force, has_torque, mode, body, cvec):
    """A fingerprint of a step's input: its loads (those given), the pointer's mode, the
    gripped body and the coupling (layout.Coupling; zeros without one).  A step whose
    input's fingerprint differs from the last step's restarts (solver.advance.bdf2)."""
    total = 0.0
    if has_force:
        total, _ = _weigh(force, 0, total)
    if has_torque:
        total, _ = _weigh(torque, force.size, total)
    k = force.size + torque.size
    for i in range(len(cvec)):
        total += (k + i + 1) * cvec[i]
    return total + 1000.0 * mode + body


@kernel(error_model="numpy")
def _momentum(inertia, rot, b, q, omega):
    """L = R I Rᵀ ω of body b at orientation q; rot (nb,3,3) scratch (row b written)."""
    qmatrix(q, rot, b)
    return matvec(rot, b, matvec(inertia, b, tmatvec(rot, b, omega)))


@kernel(error_model="numpy")
def _ahead(a, b, c):
    """a + c (a − b) for 3-tuples."""
    return add(a, scale(c, sub(a, b)))


@kernel(error_model="numpy", _nrt=False)
def ratio(opt, st, hist, load):
    """h/h_prev when st carries a usable history (hist: prev_h, prev_mark, prev_load) for
    a step whose input has the fingerprint ``load``, else 0 (solver.advance.bdf2.ratio)."""
    if hist[0] <= 0.0 or hist[2] != load:
        return 0.0
    r = opt[Opt.h] / hist[0]
    if r > R_MAX:
        return 0.0
    now = mark(st.x, st.q, st.v, st.omega, st.q_sf)
    return r if now == hist[1] else 0.0


@kernel(error_model="numpy", _nrt=False)
def predict(inertia, inv_inertia, h, r, st, prev, rot, pred):
    """pred (layout.Prediction: x, q, v, omega, shift, q_sf) ← the stage of a step h at ratio
    r from st with history prev (x, q, v, omega, q_sf; unread when r = 0); returns γ.
    rot (nb,3,3) scratch."""
    c = r * r / (1.0 + 2.0 * r)
    gamma = h * (1.0 + r) / (1.0 + 2.0 * r)
    old = prev if r > 0.0 else (st.x, st.q, st.v, st.omega, st.q_sf)
    px, pq, pv, pw, psf = old
    for b in range(len(st.x)):
        x, v, w = vec(st.x, b), vec(st.v, b), vec(st.omega, b)
        q = quat_at(st.q, b)
        pos_hat = _ahead(x, vec(px, b), c)
        turn = qlog(qmul(q, qconj(quat_at(pq, b))))
        q_hat = qnormalize(qmul(qexp(scale(c, turn)), q))
        vel_hat = _ahead(v, vec(pv, b), c)
        mom = _momentum(inertia, rot, b, q, w)
        mom_hat = _ahead(mom, _momentum(inertia, rot, b, quat_at(pq, b), vec(pw, b)), c)
        v_tilde, w_tilde = v, w
        put(pred.x, b, add(pos_hat, scale(gamma, v_tilde)))
        q_end = qnormalize(qmul(qexp(scale(gamma, w_tilde)), q_hat))
        for k in range(4):
            pred.q[b, k] = q_end[k]
        qmatrix(q_end, rot, b)
        w_hat = matvec(rot, b, matvec(inv_inertia, b, tmatvec(rot, b, mom_hat)))
        for k in range(3):
            pred.v[b, k] = vel_hat[k] - v_tilde[k]
            pred.omega[b, k] = w_hat[k] - w_tilde[k]
            pred.shift[b, k] = v_tilde[k]
            pred.shift[b, 3 + k] = w_tilde[k]
    for j in range(len(st.q_sf)):
        put(pred.q_sf, j, _ahead(vec(st.q_sf, j), vec(psf, j), c))
    return gamma


@kernel(error_model="numpy", _nrt=False)
def integrate_stage(inertia, inv_inertia, gamma, pred, vel, rot, asleep, out_pos, out_quat,
                    out_omega):  # fmt: skip
    """(solver.advance.bdf2.integrate_stage) out ← x̃ + γ δv, exp(γ δω) ⊗ q̃ and
    ω = I_w(q[t+1])⁻¹ I_w(q̃) (δω + ω̃); vel (nb,6) holds δv on entry and v = δv + ṽ on
    return.  rot holds R(q̃) on entry and R(q[t+1]) on return.  Sleeping bodies are not
    written (the caller keeps their pose)."""
    for b in range(len(out_pos)):
        if asleep[b]:
            continue
        dv = (vel[b, 0], vel[b, 1], vel[b, 2])
        dw = (vel[b, 3], vel[b, 4], vel[b, 5])
        put(out_pos, b, add(vec(pred.x, b), scale(gamma, dv)))
        q = qnormalize(qmul(qexp(scale(gamma, dw)), quat_at(pred.q, b)))
        for k in range(4):
            out_quat[b, k] = q[k]
        for k in range(6):
            vel[b, k] = vel[b, k] + pred.shift[b, k]
        w = (vel[b, 3], vel[b, 4], vel[b, 5])
        mom = matvec(rot, b, matvec(inertia, b, tmatvec(rot, b, w)))
        qmatrix(q, rot, b)
        put(out_omega, b, matvec(rot, b, matvec(inv_inertia, b, tmatvec(rot, b, mom))))


@kernel(error_model="numpy", _nrt=False)
def remember(h, load, st, out, yielded0):
    """out's history (layout.StateSet prev_*, hist) ← st's arrays, h, the fingerprint of
    out and the step's input's (solver.advance.bdf2.history): a joint that switched
    between flowing and elastic (yielded0: st's flags) keeps no q_sf history."""
    for b in range(len(st.x)):
        for k in range(3):
            out.prev_x[b, k], out.prev_v[b, k] = st.x[b, k], st.v[b, k]
            out.prev_omega[b, k] = st.omega[b, k]
        for k in range(4):
            out.prev_q[b, k] = st.q[b, k]
    for j in range(len(st.q_sf)):
        kept = yielded0[j] == out.yielded[j]
        for k in range(3):
            out.prev_q_sf[j, k] = st.q_sf[j, k] if kept else out.q_sf[j, k]
    out.hist[0] = h
    out.hist[1] = mark(out.x, out.q, out.v, out.omega, out.q_sf)
    out.hist[2] = load
