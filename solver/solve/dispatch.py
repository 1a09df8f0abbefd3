"""The step's solve: warm start by row key, then the exact, PGS or hybrid solver."""

from __future__ import annotations

import numpy as np

from solver.model import Model
from solver.rows.table import KIND_PIN, Rows
from solver.solve.direct import direct_solve
from solver.solve.hybrid import hybrid_solve
from solver.solve.pgs import pgs_solve
from solver.solve.reference import reference_solve
from solver.solve.response import dense_system
from solver.state import State


def warm_start(model: Model, state: State, rows: Rows) -> np.ndarray:
    """Last step's forces for rows with the same key, scaled by the warm-start factor."""
    opt = model.options
    lam = np.zeros(len(rows))
    if not opt.warm_start or len(state.warm_key) == 0:
        return lam
    at = np.searchsorted(state.warm_key, rows.key)
    at = np.minimum(at, len(state.warm_key) - 1)
    hit = state.warm_key[at] == rows.key
    lam[hit] = opt.warm_start_factor * state.warm_lam[at[hit]]
    return lam


def solve(model: Model, state: State, rows: Rows, resp: tuple, vel_free: np.ndarray) -> tuple:
    """(λ, velocities, iterations, residual, solver name) for the step's rows."""
    opt = model.options
    method = opt.method
    if method == "auto":  # pins' rows are iterated (hybrid): the compiled tree has no pin nodes
        method = "direct" if rows.bilateral and not np.any(rows.kind == KIND_PIN) else "hybrid"
    lam0 = warm_start(model, state, rows)
    if method == "direct":
        if not rows.bilateral:
            raise ValueError(
                "the direct solver handles two-sided rows only (no contacts or limits)"
            )
        lam, residual, ok = direct_solve(rows, resp, vel_free)
        if ok:
            return lam, apply_forces(rows, resp, vel_free, lam), 1, residual, "direct"
        lam0 = lam  # the active set did not settle: finish with PGS from there
    if method == "hybrid":
        lam, sweeps, residual = hybrid_solve(
            rows,
            resp,
            vel_free,
            lam0,
            opt.iterations,
            skip_dormant=opt.dormant_rows,
            leaves=opt.leaf_contacts,
        )
        return lam, apply_forces(rows, resp, vel_free, lam), sweeps, residual, "hybrid"
    if method == "reference":
        q, c = dense_system(rows, resp, vel_free)
        lam = reference_solve(q, c, rows.lo, rows.hi, rows.fric_of, rows.mu)
        return lam, apply_forces(rows, resp, vel_free, lam), 1, 0.0, "reference"
    lam, vel, sweeps, residual = pgs_solve(
        rows.body_a, rows.body_b, rows.jac_a, rows.jac_b, resp[0], resp[1], rows.lo, rows.hi,
        rows.comp, rows.bias, rows.fric_of, rows.mu, vel_free, lam0, opt.iterations, 1e-12,
    )  # fmt: skip
    return lam, vel, sweeps, residual, "pgs"


def apply_forces(rows: Rows, resp: tuple, vel_free: np.ndarray, lam: np.ndarray) -> np.ndarray:
    """vel_free plus the velocity response to the row forces."""
    vel = np.vstack((vel_free, np.zeros((1, 6))))
    np.add.at(vel, rows.body_a, resp[0] * lam[:, None])
    np.add.at(vel, rows.body_b, resp[1] * lam[:, None])
    return vel[:-1]
