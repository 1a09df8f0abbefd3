"""Compiled end of the step: integration, joint projection, monitor checks, rheology update.

Integration (``solver.integrate``, momentum form): with L = I_w(q[t]) ω[t+1],
    x[t+1] = x + h v,   ω_m = I_w(q_m)⁻¹ L, q_m = exp(½ h ω_m) ⊗ q  (4 fixed-point passes),
    q[t+1] = normalise(exp(h ω_m) ⊗ q),   ω ← I_w(q[t+1])⁻¹ L.
Projection (``solver.stabilize``): while a joint gap exceeds 0.1 mm (≤ 3 rounds),
solve (J M⁻¹ Jᵀ + 10⁻¹⁴) μ = −C on the anchor rows and move x += Δx, q ← exp(Δθ) ⊗ q
with Δ = M⁻¹ Jᵀ μ (the tree solve with h = 1, v_free = 0).
Monitor (``solver.monitor``): non-finite state, |v| > max_speed or |ω| >
max_angular_speed, a joint gap > max_joint_gap → the step is handed back (status ≠ 0).
Rheology (``solver.step._rheology_update``): τ = λ_s; low-passed |τ| with
α = h/(T + h); flowing joints q_sf ← ((D_d + D_f) q_sf + D_d h w)/(D_d + D_f + K_f h);
un-yield re-anchors to exp(−q_sf) ⊗ q_rel; elastic joints q_sf = log(q_rel ⊗ anchor⁻¹).
"""

from __future__ import annotations

import inspect

import numpy as np
from numba import njit

from solver.fast.kin import (
    add,
    dot,
    frames,
    matvec,
    neg,
    norm,
    put,
    qconj,
    qexp,
    qlog,
    qmatrix,
    qmul,
    qnormalize,
    qrotate,
    quat_at,
    scale,
    sub,
    tmatvec,
    vec,
)
from solver.fast.rows import anchor_rows, flowing, q_rel
from solver.fast.tree import node_rows, tree_solve
from solver.integrate import MIDPOINT_PASSES
from solver.rows import KIND_RHEOLOGY
from solver.stabilize import project_joints

# The numpy step's own settings, read once (numba freezes them into the compiled code;
# solver.fast.cache recompiles when those files change).
_PROJECT = inspect.signature(project_joints).parameters
PROJECT_TOL, PROJECT_ROUNDS = _PROJECT["tol"].default, _PROJECT["rounds"].default
PROJECT_RIDGE = 1e-14  # solver.stabilize's ridge on J M⁻¹ Jᵀ


@njit(cache=True, error_model="numpy")
def _omega_from_momentum(q, mom, inv_inertia, b, rot):
    """ω = I_w(q)⁻¹ L = R (I⁻¹ (Rᵀ L)) of body b; rot (nb,3,3) scratch."""
    qmatrix(q, rot, b)
    return matvec(rot, b, matvec(inv_inertia, b, tmatvec(rot, b, mom)))


@njit(cache=True, error_model="numpy", _nrt=False)
def integrate(inertia, inv_inertia, h, pos, quat, vel, rot, asleep, out_pos, out_quat, out_omega,
              scratch):  # fmt: skip
    """Semi-implicit Euler in momentum form with the implicit midpoint rotation rate.
    rot (nb,3,3) holds R(q[t]) on entry and R(q[t+1]) on return.  Sleeping bodies
    (asleep (nb,) bool) keep their pose, at rest.  scratch: (rates (nb,3), momenta
    (nb,3), done (nb,) bool).

    The midpoint passes run pass by pass over all bodies (the bodies' chains are
    independent, so the processor overlaps them; body by body it waits on each pass's
    latency), and a body's passes stop once one returns its rate unchanged: every later
    pass would repeat it exactly, so the result is bit for bit that of all passes."""
    nb = len(pos)
    rates, moms, done = scratch
    for b in range(nb):
        done[b] = asleep[b]
        if asleep[b]:
            for k in range(3):
                out_pos[b, k], out_omega[b, k] = pos[b, k], 0.0
            for k in range(4):
                out_quat[b, k] = quat[b, k]
            continue
        put(out_pos, b, add(vec(pos, b), scale(h, (vel[b, 0], vel[b, 1], vel[b, 2]))))
        rate = (vel[b, 3], vel[b, 4], vel[b, 5])
        put(moms, b, matvec(rot, b, matvec(inertia, b, tmatvec(rot, b, rate))))  # L = R I Rᵀ ω
        put(rates, b, rate)
    for _ in range(MIDPOINT_PASSES):
        for b in range(nb):
            if done[b]:
                continue
            rate = vec(rates, b)
            mid = qmul(qexp(scale(0.5 * h, rate)), quat_at(quat, b))
            new = _omega_from_momentum(mid, vec(moms, b), inv_inertia, b, rot)
            done[b] = new[0] == rate[0] and new[1] == rate[1] and new[2] == rate[2]
            put(rates, b, new)
    for b in range(nb):
        if asleep[b]:
            continue
        q0 = quat_at(quat, b)
        q = qnormalize(qmul(qexp(scale(h, vec(rates, b))), q0))
        for k in range(4):
            out_quat[b, k] = q[k]
        put(out_omega, b, _omega_from_momentum(q, vec(moms, b), inv_inertia, b, rot))


@njit(cache=True, error_model="numpy", inline="always")
def _gap2(joints, pos, quat, j):
    """The square of joint j's anchor distance (m²); joints: the model's joint parents,
    bones and anchors (m[0], m[1], m[2], m[3]).  Inlined (16–48 uses a step): called
    from a function with reference counting, each call counted its six arrays in and out
    (12 calls to NRT); the step runs without it now (kernel._step), the projection with."""
    p, c, anc_p, anc_c = joints[0][j], joints[1][j], joints[2], joints[3]
    a = add(vec(pos, p), qrotate(quat_at(quat, p), vec(anc_p, j))) if p >= 0 else vec(anc_p, j)
    d = sub(add(vec(pos, c), qrotate(quat_at(quat, c), vec(anc_c, j))), a)
    return dot(d, d)


@njit(cache=True, error_model="numpy", _nrt=False)
def _awake_gap2(joints, pos, quat, asleep):
    """The square of the largest anchor distance (m²) of the joints of awake bodies (0
    when none); joints as ``_gap2``'s."""
    worst = 0.0
    for j in range(len(joints[0])):
        if not asleep[joints[1][j]]:
            worst = max(worst, _gap2(joints, pos, quat, j))
    return worst


@njit(cache=True, error_model="numpy", inline="always")
def gaps_within(projected, opt):
    """After integration and ``project``: every anchor gap is known to be within the
    monitor's limit without measuring it, when nothing needed projecting (every awake
    joint within PROJECT_TOL, and PROJECT_TOL within the limit) — the sleeping joints
    have not moved since the step's first check (``state_ok`` on its start pose)."""
    return not projected and opt[10] >= PROJECT_TOL


@njit(cache=True, error_model="numpy", _nrt=False)
def state_ok(joints, opt, pos, quat, lin, ang, gaps_known):
    """False when the monitor (solver.monitor.check_state) would raise; joints as
    ``_gap2``'s.  Branch-free over the bodies: 0·x is 0 for every finite x and NaN
    otherwise, so one sum tests them all; speeds, spins and anchor gaps are compared
    squared.  gaps_known: every anchor gap is already known to be within the limit
    (the caller's ``gaps_within``), so they are not measured again."""
    poison, fast = 0.0, False
    max_speed2, max_spin2 = opt[8] * opt[8], opt[9] * opt[9]
    for b in range(len(pos)):
        for k in range(3):
            poison += 0.0 * pos[b, k] + 0.0 * lin[b, k] + 0.0 * ang[b, k]
        for k in range(4):
            poison += 0.0 * quat[b, k]
        speed2 = lin[b, 0] * lin[b, 0] + lin[b, 1] * lin[b, 1] + lin[b, 2] * lin[b, 2]
        spin2 = ang[b, 0] * ang[b, 0] + ang[b, 1] * ang[b, 1] + ang[b, 2] * ang[b, 2]
        fast = fast or speed2 > max_speed2 or spin2 > max_spin2
    if poison != 0.0 or fast:  # (NaN != 0)
        return False
    if gaps_known:
        return True
    limit2 = opt[10] * opt[10]
    within = True
    for j in range(len(joints[0])):
        within = within and _gap2(joints, pos, quat, j) <= limit2
    return within


@njit(cache=True, error_model="numpy", _nrt=False)
def response(rw, start, n, inv_mass, inv_i, h, resp_a, resp_b):
    """Velocity change per unit row force: h M⁻¹ jac, per side (0 for the world), of
    rows start … n − 1."""
    _response_side(rw[0], rw[2], start, n, inv_mass, inv_i, h, resp_a)
    _response_side(rw[1], rw[3], start, n, inv_mass, inv_i, h, resp_b)


@njit(cache=True, error_model="numpy")
def _response_side(body, jac, start, n, inv_mass, inv_i, h, out):
    for i in range(start, n):
        r = row_response(body, jac, i, inv_mass, inv_i, h)
        for k in range(6):
            out[i, k] = r[k]


@njit(cache=True, error_model="numpy")
def row_response(body, jac, i, inv_mass, inv_i, h):
    """Row i's h M⁻¹ jac on one side (zeros for the world)."""
    b = body[i]
    if b < 0:
        return (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    s0 = inv_i[b, 0, 0] * jac[i, 3] + inv_i[b, 0, 1] * jac[i, 4]
    s1 = inv_i[b, 1, 0] * jac[i, 3] + inv_i[b, 1, 1] * jac[i, 4]
    s2 = inv_i[b, 2, 0] * jac[i, 3] + inv_i[b, 2, 1] * jac[i, 4]
    return (
        h * (inv_mass[b] * jac[i, 0]), h * (inv_mass[b] * jac[i, 1]),
        h * (inv_mass[b] * jac[i, 2]), h * (s0 + inv_i[b, 0, 2] * jac[i, 5]),
        h * (s1 + inv_i[b, 1, 2] * jac[i, 5]), h * (s2 + inv_i[b, 2, 2] * jac[i, 5]),
    )  # fmt: skip


@njit(cache=True, error_model="numpy")
def apply(rw, n, resp_a, resp_b, lam, vel):
    """vel += response to λ: every row's a side, then every row's b side (np.add.at order)."""
    _apply_side(rw[0], n, resp_a, lam, vel)
    _apply_side(rw[1], n, resp_b, lam, vel)


@njit(cache=True, error_model="numpy", inline="always")
def copy6(src, dst):
    """dst[:, :] ← src (nb, 6) (an array assigned to a slice needs reference counting)."""
    for b in range(len(src)):
        for k in range(6):
            dst[b, k] = src[b, k]


@njit(cache=True, error_model="numpy", _nrt=False)
def apply_listed(rw, rows, count, resp_a, resp_b, lam, vel):
    """vel += response to λ of the rows rows[:count] only (ascending: the order of
    ``apply``)."""
    for side in range(2):
        body, resp = (rw[0], resp_a) if side == 0 else (rw[1], resp_b)
        for q in range(count):
            i = rows[q]
            if body[i] >= 0:
                for k in range(6):
                    vel[body[i], k] += resp[i, k] * lam[i]


@njit(cache=True, error_model="numpy")
def _apply_side(body, n, resp, lam, vel):
    for i in range(n):
        b = body[i]
        if b >= 0:
            for k in range(6):
                vel[b, k] += resp[i, k] * lam[i]


@njit(cache=True, error_model="numpy", inline="always")
def needs_projection(joints, pos, quat, asleep):
    """Some awake joint's anchors are more than PROJECT_TOL apart (``project``'s work;
    most steps: none).  joints as ``_gap2``'s."""
    return _awake_gap2(joints, pos, quat, asleep) > PROJECT_TOL * PROJECT_TOL


@njit(cache=True, error_model="numpy", _nrt=True)
def project(m, joints, tree, pws, pos, quat, asleep):
    """Pull joint anchors together in place (solver.stabilize.project_joints) when
    ``needs_projection`` (the caller asks first); False if the projection system is
    degenerate.  joints as ``_gap2``'s; tree = (order, parent, no_rheo, rows, size, tw);
    pws = (rows, resp_a, resp_b, rot, inv_i, inertia_w, μ) scratch.  The joints of
    sleeping bodies (asleep) are left as they are."""
    order, parent, no_rheo, rows, size, tw = tree
    prw, pa, pb, rot, inv_i, inertia_w, mu = pws
    nb = len(pos)
    zeros = np.zeros((nb, 6))
    seq, nseq, bone = np.empty(len(order), np.int64), 0, m[1]
    for i in order:
        if not (asleep[i] if i < nb else asleep[bone[i - nb]]):
            seq[nseq], nseq = i, nseq + 1
    for k in range(PROJECT_ROUNDS):
        if k > 0 and not needs_projection(joints, pos, quat, asleep):
            break
        frames(quat, m[17], m[18], rot, inertia_w, inv_i)
        n = anchor_rows(joints, pos, rot, pos, 1.0, 1.0, False, asleep, prw, 0)
        response(prw, 0, n, m[16], inv_i, 1.0, pa, pb)
        prw[6][:n] = PROJECT_RIDGE
        for i in order:
            size[i] = node_rows(i, nb, no_rheo, rows[i])
        if not tree_solve(
            seq, nseq, parent, nb, prw, zeros, 1.0, m[15], inertia_w, rows, size, tw, mu
        ):
            return False
        delta = np.zeros((nb, 6))
        apply(prw, n, pa, pb, mu, delta)
        for b in range(nb):
            for k in range(3):
                pos[b, k] = pos[b, k] + delta[b, k]
            q = qnormalize(qmul(qexp((delta[b, 3], delta[b, 4], delta[b, 5])), quat_at(quat, b)))
            for k in range(4):
                quat[b, k] = q[k]
    return True


@njit(cache=True, error_model="numpy", _nrt=False)
def rheology_update(rheo, opt, prev, rw, n, lam, vel, rheo_joint, quat, asleep, out, w):
    """q_sf, yield flags, anchors, torque filter and torques after the solve; the joints
    of sleeping bodies (asleep) keep their state (their torque reads 0: no rows).
    rheo: the model's joint parents, bones, K_f, D_f, D_d, has rheology, yield torque,
    plastic, finite yield (m[0], m[1], m[4]–m[7], m[12]–m[14]); prev: the state's q_sf,
    yield flags, anchors, torque filter (st[4:8]); w (nj, 3): scratch (the rheology rows'
    velocities)."""
    parent, bone, kf, df, dd, has, yield_, plastic, finite_yield = rheo
    q_sf0, yielded0, anchor0, avg0 = prev
    q_sf, yielded, anchor, avg, torque = out
    h = opt[0]
    nj, body_a, body_b, jac_a, jac_b, kind = len(parent), rw[0], rw[1], rw[2], rw[3], rw[11]
    torque[:, :] = 0.0
    w[:, :] = 0.0
    slot = 0
    for i in range(n):
        if kind[i] != KIND_RHEOLOGY:
            continue
        j = rheo_joint[i]
        a, b = body_a[i], body_b[i]
        wa, wb = 0.0, 0.0
        for k in range(6):
            wa += jac_a[i, k] * vel[a, k] if a >= 0 else 0.0
            wb += jac_b[i, k] * vel[b, k] if b >= 0 else 0.0
        torque[j, slot % 3] = lam[i]
        w[j, slot % 3] = wa + wb
        slot += 1
    alpha = h / (opt[7] + h)
    for j in range(nj):
        tn = norm((torque[j, 0], torque[j, 1], torque[j, 2]))
        flow0 = flowing(plastic, finite_yield, yielded0, j)
        avg[j] = avg0[j] + alpha * (tn - avg0[j])
        for k in range(3):
            q_sf[j, k] = q_sf0[j, k]
            if flow0 and has[j]:
                t = dd[j, k] + df[j, k] + kf[j, k] * h
                q_sf[j, k] = ((dd[j, k] + df[j, k]) * q_sf0[j, k] + dd[j, k] * h * w[j, k]) / t
        for k in range(4):
            anchor[j, k] = anchor0[j, k]
        can_yield = finite_yield[j] and plastic[j]
        qr = q_rel(j, parent, bone, quat)
        unyield = can_yield and yielded0[j] and avg[j] < yield_[j]
        if unyield:
            qa = qmul(qexp(neg(vec(q_sf, j))), qr)
            for k in range(4):
                anchor[j, k] = qa[k]
        if can_yield:
            yielded[j] = (not unyield) if yielded0[j] else avg[j] > yield_[j]
        else:
            yielded[j] = False
        if has[j] and not flowing(plastic, finite_yield, yielded, j):
            put(q_sf, j, qlog(qmul(qr, qconj(quat_at(anchor, j)))))
        if asleep[bone[j]]:
            _freeze(j, q_sf0, yielded0, anchor0, avg0, q_sf, yielded, anchor, avg)


@njit(cache=True, error_model="numpy")
def _freeze(j, q_sf0, yielded0, anchor0, avg0, q_sf, yielded, anchor, avg):
    """Joint j keeps its rheology and yield state (its island sleeps)."""
    for k in range(3):
        q_sf[j, k] = q_sf0[j, k]
    for k in range(4):
        anchor[j, k] = anchor0[j, k]
    yielded[j], avg[j] = yielded0[j], avg0[j]
