"""The compiled step: ``solver.step.step``'s pipeline in one call (DESIGN §3, digest §4.3).

    v_free  = v + h (g + F/m),  ω_free = ω + h I_w⁻¹ τ
    rows    = anchor | rheology | limits | contacts (normal, friction) | grip or pointer
    lam     = direct (tree elimination inside an active set: rows leaving their box are
              pinned at the bound, released when they stop pushing on it; PGS finishes
              if that does not settle) when every row is two-sided; else PGS
              warm-started with last step's λ by row key
    v, pose = integrate (momentum form), project joints (only above 0.1 mm)
    q_sf    = rheology update with the solved velocity; warm keys sorted for the next step

Packed arguments (see ``solver.fast.pack``): m model arrays, g geometry, tree the
elimination forest, ws/pws workspaces, opt/iopt options, st state arrays, inp input.
Status FALLBACK hands the step back to the numpy implementation (box–box contact, a
monitor failure that must raise, a degenerate direct system); SUBSTEP asks for
rep_i[0] equal substeps (solver.substep) before anything is computed.
"""

from __future__ import annotations

import inspect

import numpy as np
from numba import njit

from solver.direct import direct_solve
from solver.fast.clock import cycles
from solver.fast.contacts import (
    collide_pointer,
    collide_scene,
    contact_rows,
    coupling_rows,
    is_touch_row,
    world_shapes,
)
from solver.fast.flat import node_count, row_capacity, unflatten
from solver.fast.hybrid import NU_CAP, ROUNDS, hybrid_solve
from solver.fast.kin import frames, matvec
from solver.fast.post import (
    gaps_within,
    integrate,
    needs_projection,
    project,
    response,
    rheology_update,
    row_response,
    state_ok,
)
from solver.fast.rows import (
    ZERO,
    anchor_rows,
    flowing,
    is_null,
    limit_arrays,
    limit_rows,
    rheology_rows,
)
from solver.fast.tree import row_velocity
from solver.pgs import pgs_into
from solver.rows import KIND_GRIP, KIND_RHEOLOGY
from solver.sleep import settle, touch
from solver.substep import substeps_needed

OK, FALLBACK, SUBSTEP = 0, 1, 2
SOLVER_DIRECT, SOLVER_PGS, SOLVER_HYBRID = 0, 1, 2
METHOD_AUTO, METHOD_PGS, METHOD_DIRECT, METHOD_HYBRID = 0, 1, 2, 3
MODE_NONE, MODE_GRIP, MODE_TOUCH = 0, 1, 2
DIRECT_ROUNDS = inspect.signature(direct_solve).parameters["rounds"].default


STAGES = (
    "setup (frames, inertia, substep test)",
    "free velocities",
    "joint rows (anchors, rheology, limits)",
    "collision and contact/grip rows",
    "regularisation",
    "solve (and the row responses it uses)",
    "integrate, project, monitor",
    "rheology update, warm keys, report",
)
"""Stages of the step's profile (``ws[10]``: cycles per stage, summed while iopt[7])."""


@njit(cache=True, error_model="numpy")
def tick(prof, on, stage, t0):
    """Add the cycles since t0 to ``stage`` when profiling; the new mark."""
    if not on:
        return t0
    t = cycles()
    prof[stage] += t - t0
    return t


@njit(cache=True, error_model="numpy", _nrt=False)
def free_velocity(inv_mass, opt, vel, omega, inv_i, loads, out):
    """(nb,6) velocities after gravity and external loads (force, torque, flags: the
    input's inp[0], inp[1], inp[4]), before constraints."""
    force, torque, ivec = loads
    h = opt[0]
    for b in range(len(vel)):
        tau = matvec(inv_i, b, (torque[b, 0], torque[b, 1], torque[b, 2]))
        for k in range(3):
            acc = opt[12 + k] if inv_mass[b] > 0.0 else 0.0
            if ivec[3]:
                acc = acc + force[b, k] * inv_mass[b]
            out[b, k] = vel[b, k] + h * acc
            out[b, 3 + k] = omega[b, k] + h * tau[k] if ivec[4] else omega[b, k]


@njit(cache=True, error_model="numpy", inline="always")
def build_rows(joints, rheo, limits, g, opt, iopt, st, rot, vel_free, inp, ws, asleep, awake,
               limit_scratch):  # fmt: skip
    """Fill the row table; returns (rows, scene contacts, first grip row, grip rows), or
    rows = −1 when a box–box pair is within reach.  The shapes' world frames (ws[8],
    ws[9]) are already computed; asleep/awake (nb,) bool: sleeping bodies and the awake
    movable ones (solver.sleep); limit_scratch: ``limit_rows``' (gaps, turned)."""
    pos, quat = st[0], st[1]
    rw, rheo_joint, cb, centre, srot = ws[0], ws[3], ws[4], ws[8], ws[9]
    pvec, cvec, ivec = inp[2], inp[3], inp[4]
    h = opt[0]
    prof, on = ws[10], iopt[7]
    t = cycles() if on else 0
    n = anchor_rows(joints, pos, rot, st[3], h, opt[1], True, asleep, rw, 0)
    if iopt[3]:
        n = rheology_rows(rheo, quat, rot, h, st[4], st[5], st[6], asleep, rheo_joint, rw, n)
    if iopt[4]:
        gaps, turned = limit_scratch
        n = limit_rows(limits, quat, rot, h, opt[1], opt[5], asleep, rw, n, gaps, turned)
    tick(prof, on, 2, t)
    ncontact = 0
    if iopt[5]:
        ncontact = collide_scene(g, centre, srot, opt[4], cb, iopt[8], awake)
        if ncontact < 0:
            return -1, 0, 0, 0
        n = contact_rows(cb, 0, ncontact, pos, vel_free, ZERO, h, opt[2], opt[3], rw, n)
    if ivec[0] == MODE_GRIP:
        ptr = (
            (pvec[0], pvec[1], pvec[2]),
            (pvec[3], pvec[4], pvec[5], pvec[6]),
            (pvec[7], pvec[8], pvec[9]),
            (pvec[10], pvec[11], pvec[12]),
        )
        cpl = (
            (cvec[0], cvec[1], cvec[2]),
            (cvec[3], cvec[4], cvec[5]),
            (cvec[6], cvec[7], cvec[8], cvec[9]),
            cvec[10],
            cvec[11],
            cvec[12],
            cvec[13],
            cvec[14],
            cvec[15],
        )
        grip0 = n
        n = coupling_rows(pos, quat, h, ptr, cpl, ivec[1], ivec[2], rw, n)
        return n, ncontact, grip0, n - grip0
    if ivec[0] == MODE_TOUCH:
        u = (pvec[7], pvec[8], pvec[9])
        pc = (pvec[0] - h * u[0], pvec[1] - h * u[1], pvec[2] - h * u[2])
        end = collide_pointer(g, centre, srot, pc, pvec[13], opt[4], cb, ncontact)
        n = contact_rows(cb, ncontact, end, pos, vel_free, u, h, opt[2], opt[3], rw, n)
    return n, ncontact, n, 0


@njit(cache=True, error_model="numpy", _nrt=False)
def regularize(rw, n, inv_mass, inv_i, h, eps):
    """comp ← ε·A_ii on every row without compliance of its own, A_ii = J_i h M⁻¹ J_iᵀ
    from each side's ``row_response`` in registers (what ``response`` stores, which is
    made only for the rows a solver reads)."""
    if eps <= 0.0:
        return
    for i in range(n):
        if not rw[6][i] > 0.0:
            d = 0.0
            ra = row_response(rw[0], rw[2], i, inv_mass, inv_i, h)
            rb = row_response(rw[1], rw[3], i, inv_mass, inv_i, h)
            for k in range(6):
                d += rw[2][i, k] * ra[k] + rw[3][i, k] * rb[k]
            rw[6][i] = eps * d


@njit(cache=True, error_model="numpy", inline="always")
def warm_start(opt, iopt, warm, rw, n, lam):
    """lam[:n] ← last step's λ of rows with the same key × factor (``_warm_fill``), 0 for
    the others."""
    lam[:n] = 0.0
    if iopt[2] and len(warm[0]) > 0:
        _warm_fill(opt[11], warm[0], warm[1], rw[10], n, lam)


@njit(cache=True, error_model="numpy", _nrt=False)
def _warm_fill(factor, keys, values, row_key, n, lam):
    """lam[i] ← factor × the λ of key row_key[i] in (keys, values), where found.  The keys
    are sorted and the rows are made nearly in key order, so the key after the last one
    found is tried first (a binary search otherwise)."""
    at = -1  # where the last key was found
    for i in range(n):
        key = row_key[i]
        if at + 1 < len(keys) and keys[at + 1] == key:
            at += 1
        else:
            found = min(np.searchsorted(keys, key), len(keys) - 1)
            if keys[found] != key:
                continue
            at = found
        lam[i] = factor * values[at]


@njit(cache=True, error_model="numpy", _nrt=False)
def direct(bw, tree, h, rw, n, ne, vel_free, lam0, grip, asleep, sv, lam, vel):
    """(code, residual) as solver.direct.direct_solve on a table of ne joint rows and
    then grip rows only, λ into lam[:n] and the velocities into vel: a primal active set
    on the box-QP, the hybrid's exact rounds with nothing to iterate (hybrid_solve: pinned
    grip rows' forces folded into v_free, the joints and free grip rows solved by the
    tree, its velocities taken from the tree; a pinned row released when its residual
    r = J v + C λ + β no longer pushes against the bound, a free one that leaves its box
    pinned; ≤ DIRECT_ROUNDS rounds).  residual: max |r| over the free rows.  code 0:
    settled; 1: not settled (λ clipped, PGS finishes); 2: degenerate, or a row that is
    neither (fall back)."""
    for i in range(ne, n):
        if rw[11][i] != KIND_GRIP:
            return 2, 0.0
    code, _, _ = hybrid_solve(
        bw, tree, h, rw, n, ne, vel_free, lam0, 0, grip, False, asleep, sv, lam, vel,
        DIRECT_ROUNDS,
    )  # fmt: skip
    if code != 0:
        return code, 0.0
    at_lo, at_hi = sv[0][0], sv[0][1]
    residual = 0.0
    for i in range(n):
        if not (at_lo[i] or at_hi[i]):
            residual = max(residual, abs(row_velocity(rw, i, vel) + rw[6][i] * lam[i] + rw[7][i]))
    return 0, residual


@njit(cache=True, error_model="numpy", inline="always")
def solve(bw, tree, rw, opt, iopt, warm, n, vel_free, grip, asleep, sv, lam0, lam, vel):
    """(status, iterations, residual, solver) as solver.step.solve; λ into lam[:n], the
    velocities into vel.  The row responses (bw[3], bw[4]) are made here, for the rows
    the solver reads: only the rows after the joints' for the hybrid and direct solves,
    whose joint rows the tree solves from their Jacobians, all of them for PGS (and for
    the PGS that finishes a direct solve whose active set did not settle).

    bw: the model arrays the solvers read (joint_bone, mass, inverse mass, row responses
    a and b, world inverse inertia, world inertia: m[1], m[15], m[16], ws[1], ws[2],
    ws[6], ws[7]); warm: the last step's (keys, λ); lam0 (≥ n): the warm start, made
    here; sv: the solvers' scratch arrays (step_arrays), so none of them allocates."""
    lo, hi, fric, kind = rw[4], rw[5], rw[8], rw[11]
    bilateral = True
    for i in range(n):
        if not (lo[i] < 0.0 and hi[i] > 0.0 and fric[i] < 0):
            bilateral = False
    method = iopt[0]
    hybrid = method == METHOD_HYBRID or (method == METHOD_AUTO and not bilateral)
    exact = method == METHOD_DIRECT or (method == METHOD_AUTO and bilateral)
    ne = 0
    while (hybrid or exact) and ne < n and kind[ne] <= KIND_RHEOLOGY:
        ne += 1
    response(rw, ne, n, bw[2], bw[5], opt[0], bw[3], bw[4])  # (the tree needs none)
    warm_start(opt, iopt, warm, rw, n, lam0)
    if exact:
        if not bilateral:
            return FALLBACK, 0, 0.0, SOLVER_DIRECT
        code, residual = direct(
            bw, tree, opt[0], rw, n, ne, vel_free, lam0, grip, asleep, sv, lam, vel
        )
        if code == 2:
            return FALLBACK, 0, 0.0, SOLVER_DIRECT
        if code == 0:
            return OK, 1, residual, SOLVER_DIRECT
        response(rw, 0, ne, bw[2], bw[5], opt[0], bw[3], bw[4])  # PGS reads every row's
        for i in range(n):
            lam0[i] = lam[i]
    if hybrid:
        code, sweeps, residual = hybrid_solve(
            bw, tree, opt[0], rw, n, ne, vel_free, lam0, iopt[1], grip, iopt[9], asleep, sv, lam,
            vel, ROUNDS,
        )  # fmt: skip
        return (OK if code != 2 else FALLBACK), sweeps, residual, SOLVER_HYBRID
    sweeps, residual = pgs_into(
        n, rw[0], rw[1], rw[2], rw[3], bw[3], bw[4], rw[4], rw[5], rw[6], rw[7], rw[8], rw[9],
        vel_free, lam0, iopt[1], 1e-12, lam, vel, sv[2][0],
    )  # fmt: skip
    return OK, sweeps, residual, SOLVER_PGS


@njit(cache=True, error_model="numpy", _nrt=False)
def report(rw, n, lam, rep_f):
    """rep_f[1:4] grip force, [4:7] grip torque, [7:10] pointer touch force."""
    for i in range(n):
        if rw[11][i] == KIND_GRIP:
            slot = rw[10][i] & 0xF
            rep_f[1 + slot] = lam[i]
        elif is_touch_row(rw[10][i], rw[11][i]):
            for k in range(3):
                rep_f[7 + k] += rw[3][i, k] * lam[i]


@njit(cache=True, error_model="numpy")
def step_kernel(flat, st, inp, out, rep_i, rep_f):
    """One step of st into the caller's arrays (entry points: ``solver.fast.entry``).

    st (x, q, v, ω, q_sf, yielded, anchor, τ_avg, warm keys, warm λ, asleep, still);
    out (x, q, v, ω, q_sf, yielded, anchor, τ_avg, τ, asleep, still) is written and must not
    share memory with st (read throughout, intact when the step is handed back); rep_i (4,) (rows,
    contacts, iterations, solver) and rep_f (10,) (residual, grip f, grip τ, touch f) are
    zeroed, then filled.  Returns (status, out, warm keys, warm λ, rep_i, rep_f); the warm
    keys and λ must be fresh arrays (fast_step keeps them in the State, and the model's
    arrays are views that must not reach Python: solver.fast.flat).

    This function makes the step's arrays; the step itself is ``_step``, compiled without
    numba's reference counting (``_nrt=False``): with it, every array bound to a name in
    the inlined parts, and every array of a tuple handed to one, cost two calls to NRT's
    counters (~4,400 a step on the doll, ~11 % of its time), although the model's views
    have no owner to count.  Whatever allocates runs in functions of its own that keep
    the counting (the projection, the substep test, sleeping, a Schur complement of more
    than hybrid.NU_CAP rows); the solvers work in the step's scratch arrays."""
    nodes = node_count(flat)
    scratch, keys, values = step_arrays(len(st[0]), len(st[4]), row_capacity(flat), nodes)
    status, count = _step(flat, st, inp, out, rep_i, rep_f, scratch, keys, values)
    if status != OK:
        return _handed_back(status, out, rep_i, rep_f)
    return OK, out, keys[:count], values[:count], rep_i, rep_f


@njit(cache=True, error_model="numpy")
def step_arrays(nb, nj, rows, nodes):
    """The arrays ``_step`` works in, for nb bodies, nj joints, room for ``rows`` rows and
    a forest of ``nodes`` nodes: (scratch, warm keys, warm λ), scratch as ``_step`` reads
    it.  step_kernel makes them every step; a Sim once, kept in its flat buffers
    (entry.SIM_SCHEMA)."""
    b, i = np.bool_, np.int64
    solvers = (
        (np.empty(rows, b), np.empty(rows, b), np.empty(rows, b)),
        (np.empty(rows, i), np.empty(rows, i), np.empty(rows, i), np.empty(rows, i),
         np.empty(nodes, i), np.empty(nodes, i), np.empty(6, i)),
        (np.empty(rows), np.empty(rows), np.empty(rows), np.empty(rows), np.empty(rows),
         np.empty(rows), np.empty(rows)),
        (np.empty((nb, 6)), np.empty((nb, 6))),
        np.empty(NU_CAP * NU_CAP),
    )  # fmt: skip
    scratch = (
        np.empty((nb, 6)), np.empty(nb, b), np.empty(nb, b), (np.empty(nb, b), np.empty(4)),
        np.empty(rows), np.empty(rows), np.empty((nb, 6)),
        (np.empty((nb, 3)), np.empty((nb, 3)), np.empty(nb, b)),
        np.empty((nj, 3)), (np.empty((nj, 3)), np.empty((nj, 3))), np.empty(nj, b), solvers,
    )  # fmt: skip
    return scratch, np.empty(rows, np.int64), np.empty(rows)


@njit(cache=True, error_model="numpy", _nrt=False)
def _step(flat, st, inp, out, rep_i, rep_f, scratch, keys, values):
    """``step_kernel``'s step, the model's packed tuples rebuilt from its flat buffers
    here (solver.fast.flat); returns (status, warm rows in keys/values).  The step's parts
    that take those tuples are inlined into it (``inline="always"``) or called, compiled
    without reference counting too.  scratch: v_free (nb,6), fresh and awake (nb,) bool,
    wake's (loaded, pointer), warm λ and λ (rows), v (nb,6), integrate's, rheology's w
    (nj,3), limit_rows' (gaps, turned), flowing joints (nj,) bool, the solvers' (``solve``):
    whatever they hold on entry (a Sim passes the same arrays every step:
    ``step_arrays``) is overwritten before it is read."""
    m, g, tree, ptree, ws, pws, opt, iopt = unflatten(flat)
    vel_free, fresh, awake, wake_scratch, lam0, lam, vel = scratch[:7]
    integrate_scratch, w, limit_scratch, flows, sv = scratch[7:]
    pos, quat = st[0], st[1]
    nb = len(pos)
    rw, rot, inv_i, inertia_w = ws[0], ws[5], ws[6], ws[7]
    joints = (m[0], m[1], m[2], m[3])  # parents, bones, anchors (post._gap2)
    rheo = (m[0], m[1], m[4], m[5], m[6], m[7], m[12], m[13], m[14])  # post.rheology_update
    out[5][:] = False
    fresh[:] = False
    rep_i[:] = 0
    rep_f[:] = 0
    prof, on = ws[10], iopt[7]
    t = cycles() if on else 0
    nsub = substeps_needed(opt[0], iopt[6], m[0], m[1], m[16], m[20], st[8], st[9])
    if nsub > 1:
        rep_i[0] = nsub
        return SUBSTEP, 0
    frames(quat, m[17], m[18], rot, inertia_w, inv_i)
    if iopt[5] or inp[4][0] == MODE_TOUCH or iopt[10]:
        world_shapes(g, pos, quat, ws[8], ws[9])
    asleep = out[9]
    wake(m[19], (g[0], g[6], g[7], g[8]), opt, iopt, st, inp, ws[8], out[9], out[10], fresh,
         wake_scratch)  # fmt: skip
    movable = m[16]
    for b in range(nb):
        awake[b] = movable[b] > 0.0 and not asleep[b]
    t = tick(prof, on, 0, t)
    free_velocity(m[16], opt, st[2], st[3], inv_i, (inp[0], inp[1], inp[4]), vel_free)
    for b in range(nb):
        if asleep[b]:
            vel_free[b, :] = 0.0
    t = tick(prof, on, 1, t)
    joint_part = prof[2]
    n, ncontact, grip0, ngrip = build_rows(
        joints, rheo, limit_arrays(m), g, opt, iopt, st, rot, vel_free, inp, ws, asleep, awake,
        limit_scratch,
    )  # fmt: skip
    if n < 0:
        return FALLBACK, 0
    t = tick(prof, on, 3, t + (prof[2] - joint_part))  # build_rows timed its joint rows (2)
    regularize(rw, n, m[16], inv_i, opt[0], opt[6])
    t = tick(prof, on, 4, t)
    grip = (grip0, ngrip, inp[4][1])
    bw = (m[1], m[15], m[16], ws[1], ws[2], inv_i, inertia_w)
    status, iters, residual, used = solve(
        bw, tree, rw, opt, iopt, (st[8], st[9]), n, vel_free, grip, asleep, sv, lam0, lam, vel
    )
    t = tick(prof, on, 5, t)
    if status or not state_ok(joints, opt, pos, quat, vel[:, :3], vel[:, 3:], False):
        return FALLBACK, 0
    integrate(m[17], m[18], opt[0], pos, quat, vel, rot, asleep, out[0], out[1], out[3],
              integrate_scratch)  # fmt: skip
    projected = needs_projection(joints, out[0], out[1], asleep)
    if projected and not project(m, joints, ptree, pws, out[0], out[1], asleep):
        return FALLBACK, 0
    gaps_known = gaps_within(projected, opt)
    if not state_ok(joints, opt, out[0], out[1], vel[:, :3], out[3], gaps_known):
        return FALLBACK, 0
    for b in range(nb):  # (an array assigned to a slice needs reference counting)
        for k in range(3):
            out[2][b, k] = vel[b, k]
    t = tick(prof, on, 6, t)
    rheology_update(rheo, opt, st[4:8], rw, n, lam, vel, ws[3], out[1], asleep, out[4:9], w)
    if iopt[10]:
        flowing_joints(m[7], m[13], m[14], out[5], flows)
        settle(m[19], asleep, out[10], out[2], out[3], m[1], flows, opt[0], opt[15], opt[16],
               opt[17], fresh)  # fmt: skip
    count = warm_table(rw, n, lam, keys, values)
    rep_i[0], rep_i[1], rep_i[2], rep_i[3] = count, ncontact, iters, used
    rep_f[0] = residual
    report(rw, n, lam, rep_f)
    tick(prof, on, 7, t)
    return OK, count


@njit(cache=True, error_model="numpy")
def _handed_back(status, out, rep_i, rep_f):
    """step_kernel's result for a step it hands back: no warm keys or λ (the empty
    arrays made only then, not every step)."""
    return status, out, np.empty(0, dtype=np.int64), np.empty(0), rep_i, rep_f


@njit(cache=True, error_model="numpy", _nrt=False)
def warm_table(rw, n, lam, keys, values):
    """keys[:count], values[:count] ← the keys and λ of the rows that are not empty slots
    (solver.sleep), sorted by key for the next step's binary search; returns count.  Keys
    are unique and the table is built nearly in key order, so an insertion sort costs
    little more than the copy."""
    count = 0
    for i in range(n):
        if not is_null(rw, i):
            keys[count], values[count] = rw[10][i], lam[i]
            count += 1
    for i in range(1, count):
        key, value, k = keys[i], values[i], i - 1
        while k >= 0 and keys[k] > key:
            keys[k + 1], values[k + 1] = keys[k], values[k]
            k -= 1
        keys[k + 1], values[k + 1] = key, value
    return count


@njit(cache=True, error_model="numpy", inline="always")
def wake(island, shapes, opt, iopt, st, inp, centre, asleep, still, fresh, scratch):
    """asleep, still (nb,) ← the state's, then wake what this step touches (solver.sleep:
    loads, the grip, a free pointer, moving neighbours); all awake when sleeping is off.
    island: m[19]; shapes: the geometry's shape bodies, bounds and pairs (g[0], g[6],
    g[7], g[8]); scratch: (loaded (nb,) bool, pointer (4,))."""
    nb, was_asleep, was_still = len(asleep), st[10], st[11]
    for b in range(nb):
        asleep[b], still[b] = (was_asleep[b], was_still[b]) if iopt[10] else (False, 0.0)
    if not iopt[10]:
        return
    force, torque, pvec, ivec = inp[0], inp[1], inp[2], inp[4]
    loaded, pointer = scratch
    loaded[:] = False
    for b in range(nb):
        for k in range(3):
            if (ivec[3] and force[b, k] != 0.0) or (ivec[4] and torque[b, k] != 0.0):
                loaded[b] = True
    pointer[:] = 0.0
    if ivec[0] == MODE_TOUCH:
        for k in range(3):
            pointer[k] = pvec[k] - opt[0] * pvec[7 + k]
        pointer[3] = pvec[13]
    grip_body = ivec[1] if ivec[0] == MODE_GRIP else -1
    shape_body, bound, pair_f, pair_s = shapes
    touch(island, asleep, still, fresh, loaded, grip_body, pointer, centre, bound, shape_body,
          pair_f, pair_s, opt[4], st[2], st[3], opt[15], opt[16])  # fmt: skip


@njit(cache=True, error_model="numpy", inline="always")
def flowing_joints(has, plastic, finite_yield, yielded, out):
    """out (nj,) bool ← joints with rheology on the three-element rows
    (solver.joints.flowing); has, plastic, finite_yield: m[7], m[13], m[14]."""
    nj = len(has)
    for j in range(nj):
        out[j] = has[j] and flowing(plastic, finite_yield, yielded, j)
    return out
