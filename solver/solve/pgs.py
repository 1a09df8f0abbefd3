"""Projected Gauss-Seidel on the row table, warm-started (the paper's solver).

Each sweep visits rows in order and sets
    λ_i ← proj_[lo_i, hi_i](λ_i − r_i / (A_ii + comp_i)),
    r_i = jac_i·v + comp_i·λ_i + bias_i,
then pushes the change into the bodies' velocities.  Friction rows take bounds
±μ·λ_normal from their normal row's current force.  Sweeps stop early when no
row changed its velocity by more than ``tol``.

The residual reported is max_i |λ_i − proj(λ_i − r_i/d_i)|·d_i in velocity units
(m/s or rad/s): zero exactly at a solution of the mixed LCP.
"""

from __future__ import annotations

import numpy as np

from solver.jit import kernel


@kernel()
def _bounds(i, lam, lo, hi, fric_of, mu):
    f = fric_of[i]
    if f >= 0:
        b = mu[i] * lam[f]
        return -b, b
    return lo[i], hi[i]


@kernel()
def _row_velocity(i, vel, body_a, body_b, jac_a, jac_b):
    w = 0.0
    a = body_a[i]
    b = body_b[i]
    if a >= 0:
        for k in range(6):
            w += jac_a[i, k] * vel[a, k]
    if b >= 0:
        for k in range(6):
            w += jac_b[i, k] * vel[b, k]
    return w


@kernel()
def _push(i, dlam, vel, body_a, body_b, resp_a, resp_b):
    a = body_a[i]
    b = body_b[i]
    if a >= 0:
        for k in range(6):
            vel[a, k] += resp_a[i, k] * dlam
    if b >= 0:
        for k in range(6):
            vel[b, k] += resp_b[i, k] * dlam


@kernel()
def pgs_solve(
    body_a, body_b, jac_a, jac_b, resp_a, resp_b, lo, hi, comp, bias, fric_of, mu,
    vel_free, lam0, iterations, tol,
):  # fmt: skip
    """Returns (lam, vel, sweeps, residual); vel = vel_free + response to lam."""
    n = body_a.shape[0]
    lam, vel = np.empty(n), np.empty_like(vel_free)
    sweeps, residual = pgs_into(
        n, body_a, body_b, jac_a, jac_b, resp_a, resp_b, lo, hi, comp, bias, fric_of, mu,
        vel_free, lam0, iterations, tol, lam, vel, np.empty(n),
    )  # fmt: skip
    return lam, vel, sweeps, residual


@kernel(_nrt=False)
def pgs_into(
    n, body_a, body_b, jac_a, jac_b, resp_a, resp_b, lo, hi, comp, bias, fric_of, mu,
    vel_free, lam0, iterations, tol, lam, vel, diag,
):  # fmt: skip
    """``pgs_solve`` on the first n rows of the arrays, allocating nothing: λ into lam[:n],
    the velocities into vel (the shape of vel_free); diag (≥ n) is scratch.  Returns
    (sweeps, residual)."""
    for b in range(vel_free.shape[0]):
        for k in range(6):
            vel[b, k] = vel_free[b, k]
    for i in range(n):
        lam[i] = lam0[i]
    for i in range(n):
        d = comp[i]
        for k in range(6):
            d += jac_a[i, k] * resp_a[i, k] + jac_b[i, k] * resp_b[i, k]
        diag[i] = d if d > 1e-300 else 1e-300
        if lam[i] != 0.0:
            _push(i, lam[i], vel, body_a, body_b, resp_a, resp_b)
    sweeps = 0
    for _ in range(iterations):
        sweeps += 1
        change = 0.0
        for i in range(n):
            r = _row_velocity(i, vel, body_a, body_b, jac_a, jac_b) + comp[i] * lam[i] + bias[i]
            lo_i, hi_i = _bounds(i, lam, lo, hi, fric_of, mu)
            new = min(max(lam[i] - r / diag[i], lo_i), hi_i)
            dlam = new - lam[i]
            if dlam != 0.0:
                _push(i, dlam, vel, body_a, body_b, resp_a, resp_b)
                lam[i] = new
                change = max(change, abs(dlam) * diag[i])
        if change < tol:
            break
    residual = 0.0
    for i in range(n):
        r = _row_velocity(i, vel, body_a, body_b, jac_a, jac_b) + comp[i] * lam[i] + bias[i]
        lo_i, hi_i = _bounds(i, lam, lo, hi, fric_of, mu)
        target = min(max(lam[i] - r / diag[i], lo_i), hi_i)
        residual = max(residual, abs(lam[i] - target) * diag[i])
    return sweeps, residual


@kernel()
def dense_pgs(q, c, lo, hi, fric_of, mu, lam0, iterations, tol):
    """Projected Gauss–Seidel on a dense mixed LCP r = Qλ + c (Q symmetric, Q_ii > 0).

    The same projection as ``pgs_solve`` (friction rows bounded by ±μ·λ of their normal
    row, fric_of indexing into this system), sweeping the rows in order with the full
    row of Q.  Returns (λ, sweeps, residual), the residual as in ``pgs_solve``:
    max_i |λ_i − proj(λ_i − r_i/Q_ii)|·Q_ii.
    """
    n = len(c)
    lam = np.empty(n)
    sweeps, residual = dense_pgs_into(n, q, c, lo, hi, fric_of, mu, lam0, iterations, tol, lam,
                                      np.empty(n))  # fmt: skip
    return lam, sweeps, residual


@kernel(_nrt=False)
def dense_pgs_into(n, q, c, lo, hi, fric_of, mu, lam0, iterations, tol, lam, r):
    """``dense_pgs`` on the first n rows, allocating nothing: λ into lam[:n]; r (≥ n) is
    scratch.  Returns (sweeps, residual)."""
    for i in range(n):
        lam[i] = lam0[i]
        r[i] = c[i]
    for i in range(n):
        if lam[i] != 0.0:
            for k in range(n):
                r[k] += q[k, i] * lam[i]
    sweeps = 0
    for _ in range(iterations):
        sweeps += 1
        change = 0.0
        for i in range(n):
            d = q[i, i] if q[i, i] > 1e-300 else 1e-300
            lo_i, hi_i = _bounds(i, lam, lo, hi, fric_of, mu)
            new = min(max(lam[i] - r[i] / d, lo_i), hi_i)
            dlam = new - lam[i]
            if dlam != 0.0:
                for k in range(n):
                    r[k] += q[k, i] * dlam
                lam[i] = new
                change = max(change, abs(dlam) * d)
        if change < tol:
            break
    residual = 0.0
    for i in range(n):
        ri = c[i]  # recomputed, not the running sum: the residual is the solution's own
        for k in range(n):
            ri += q[i, k] * lam[k]
        lo_i, hi_i = _bounds(i, lam, lo, hi, fric_of, mu)
        d = q[i, i] if q[i, i] > 1e-300 else 1e-300
        target = min(max(lam[i] - ri / d, lo_i), hi_i)
        residual = max(residual, abs(lam[i] - target) * d)
    return sweeps, residual
