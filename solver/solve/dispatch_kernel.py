"""Compiled solver choice and warm start (the twin of the numpy step's solve and
warm_start): direct, PGS or hybrid, per step.
"""

from __future__ import annotations

import inspect

import numpy as np

from solver.compiled.layout import IOpt, Opt
from solver.jit import kernel
from solver.rows.table import KIND_GRIP, KIND_PIN, KIND_RHEOLOGY
from solver.rows.table_kernel import is_null
from solver.solve.direct import direct_solve
from solver.solve.direct_kernel import row_velocity
from solver.solve.hybrid_kernel import ROUNDS, hybrid_solve
from solver.solve.pgs import pgs_into
from solver.solve.response_kernel import response, row_response

SOLVER_DIRECT, SOLVER_PGS, SOLVER_HYBRID = 0, 1, 2


METHOD_AUTO, METHOD_PGS, METHOD_DIRECT, METHOD_HYBRID = 0, 1, 2, 3


DIRECT_ROUNDS = inspect.signature(direct_solve).parameters["rounds"].default


@kernel(error_model="numpy", _nrt=False)
def regularize(rw, n, inv_mass, inv_i, h, eps):
    """comp ← ε·A_ii on every row without compliance of its own, A_ii = J_i h M⁻¹ J_iᵀ
    from each side's ``row_response`` in registers (what ``response`` stores, which is
    made only for the rows a solver reads)."""
    if eps <= 0.0:
        return
    for i in range(n):
        if not rw.comp[i] > 0.0:
            d = 0.0
            ra = row_response(rw.body_a, rw.jac_a, i, inv_mass, inv_i, h)
            rb = row_response(rw.body_b, rw.jac_b, i, inv_mass, inv_i, h)
            for k in range(6):
                d += rw.jac_a[i, k] * ra[k] + rw.jac_b[i, k] * rb[k]
            rw.comp[i] = eps * d


@kernel(error_model="numpy", inline="always")
def warm_start(opt, iopt, warm, rw, n, lam):
    """lam[:n] ← last step's λ of rows with the same key × factor (``_warm_fill``), 0 for
    the others."""
    lam[:n] = 0.0
    keys, values = warm
    if iopt[IOpt.warm_start] and len(keys) > 0:
        _warm_fill(opt[Opt.warm_start_factor], keys, values, rw.key, n, lam)


@kernel(error_model="numpy", _nrt=False)
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


@kernel(error_model="numpy", _nrt=False)
def direct(bw, tree, h, rw, n, ne, vel_free, lam0, grip, asleep, sv, lam, vel):
    """(code, residual) as solver.solve.direct.direct_solve on a table of ne joint rows and
    then grip rows only, λ into lam[:n] and the velocities into vel: a primal active set
    on the box-QP, the hybrid's exact rounds with nothing to iterate (hybrid_solve: pinned
    grip rows' forces folded into v_free, the joints and free grip rows solved by the
    tree, its velocities taken from the tree; a pinned row released when its residual
    r = J v + C λ + β no longer pushes against the bound, a free one that leaves its box
    pinned; ≤ DIRECT_ROUNDS rounds).  residual: max |r| over the free rows.  code 0:
    settled; 1: not settled (λ clipped, PGS finishes); 2: degenerate, or a row that is
    neither (fall back)."""
    for i in range(ne, n):
        if rw.kind[i] != KIND_GRIP:
            return 2, 0.0
    code, _, _ = hybrid_solve(
        bw, tree, h, rw, n, ne, vel_free, lam0, 0, grip, (False, False), asleep, sv, lam, vel,
        DIRECT_ROUNDS,
    )  # fmt: skip
    if code != 0:
        return code, 0.0
    at_lo, at_hi = sv.flags.at_lo, sv.flags.at_hi
    residual = 0.0
    for i in range(n):
        if not (at_lo[i] or at_hi[i]):
            residual = max(
                residual, abs(row_velocity(rw, i, vel) + rw.comp[i] * lam[i] + rw.bias[i])
            )
    return 0, residual


@kernel(error_model="numpy", inline="always")
def solve(bw, tree, rw, opt, iopt, warm, n, vel_free, grip, asleep, sv, lam0, lam, vel):
    """(status, iterations, residual, solver) as solver.solve.dispatch.solve; λ into lam[:n], the
    velocities into vel.  The row responses (bw.resp_a, bw.resp_b) are made here, for the rows
    the solver reads: only the rows after the joints' for the hybrid and direct solves,
    whose joint rows the tree solves from their Jacobians, all of them for PGS (and for
    the PGS that finishes a direct solve whose active set did not settle).

    bw: the model arrays the solvers read (joint_bone, mass, inverse mass, row responses
    a and b, world inverse inertia, world inertia: layout.Bodies); warm: the last step's
    (keys, λ); lam0 (≥ n): the warm start, made here; sv: the solvers' scratch arrays
    (layout.SolverScratch), so none of them allocates."""
    lo, hi, fric, kind = rw.lo, rw.hi, rw.fric_of, rw.kind
    bilateral, pinned = True, False
    for i in range(n):
        if not (lo[i] < 0.0 and hi[i] > 0.0 and fric[i] < 0):
            bilateral = False
        pinned = pinned or kind[i] == KIND_PIN  # pins are iterated (solver.solve.dispatch)
    method = iopt[IOpt.method]
    hybrid = method == METHOD_HYBRID or (method == METHOD_AUTO and not (bilateral and not pinned))
    exact = method == METHOD_DIRECT or (method == METHOD_AUTO and bilateral and not pinned)
    ne = 0
    while (hybrid or exact) and ne < n and kind[ne] <= KIND_RHEOLOGY:
        ne += 1
    response(
        rw, ne, n, bw.inv_mass, bw.inv_inertia, opt[Opt.h], bw.resp_a, bw.resp_b
    )  # (the tree needs none)
    warm_start(opt, iopt, warm, rw, n, lam0)
    if exact:
        if not bilateral:
            return FALLBACK, 0, 0.0, SOLVER_DIRECT
        code, residual = direct(
            bw, tree, opt[Opt.h], rw, n, ne, vel_free, lam0, grip, asleep, sv, lam, vel
        )
        if code == 2:
            return FALLBACK, 0, 0.0, SOLVER_DIRECT
        if code == 0:
            return OK, 1, residual, SOLVER_DIRECT
        response(
            rw, 0, ne, bw.inv_mass, bw.inv_inertia, opt[Opt.h], bw.resp_a, bw.resp_b
        )  # PGS reads every row's
        for i in range(n):
            lam0[i] = lam[i]
    if hybrid:
        code, sweeps, residual = hybrid_solve(
            bw, tree, opt[Opt.h], rw, n, ne, vel_free, lam0, iopt[IOpt.iterations], grip,
            (iopt[IOpt.dormant_rows], iopt[IOpt.leaf_contacts]), asleep, sv, lam, vel, ROUNDS,
        )  # fmt: skip
        return (OK if code != 2 else FALLBACK), sweeps, residual, SOLVER_HYBRID
    sweeps, residual = pgs_into(
        n, rw.body_a, rw.body_b, rw.jac_a, rw.jac_b, bw.resp_a, bw.resp_b, rw.lo, rw.hi, rw.comp,
        rw.bias, rw.fric_of, rw.mu, vel_free, lam0, iopt[IOpt.iterations], 1e-12, lam, vel,
        sv.values.s_vec,
    )  # fmt: skip
    return OK, sweeps, residual, SOLVER_PGS


@kernel(error_model="numpy", _nrt=False)
def warm_table(rw, n, lam, keys, values):
    """keys[:count], values[:count] ← the keys and λ of the rows that are not empty slots
    (solver.advance.sleep), sorted by key for the next step's binary search; returns count.  Keys
    are unique and the table is built nearly in key order, so an insertion sort costs
    little more than the copy."""
    count = 0
    for i in range(n):
        if not is_null(rw, i):
            keys[count], values[count] = rw.key[i], lam[i]
            count += 1
    for i in range(1, count):
        key, value, k = keys[i], values[i], i - 1
        while k >= 0 and keys[k] > key:
            keys[k + 1], values[k + 1] = keys[k], values[k]
            k -= 1
        keys[k + 1], values[k + 1] = key, value
    return count


OK, FALLBACK, SUBSTEP, RESTART = 0, 1, 2, 3
