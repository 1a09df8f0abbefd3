"""Row response: how a unit row force changes body velocities over one step.

For row i on bodies a, b:  Δ(v, ω)_a = h·M_a⁻¹·jac_a[i]·λ_i  (and likewise b), with
M⁻¹ = diag(1/m, I_world⁻¹), I_world⁻¹ = R I_body⁻¹ Rᵀ.  The LCP matrix of the
digest is A = h·J M⁻¹ Jᵀ, so A_ij = jac_i · resp_j over the bodies they share.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from solver.rows.table import Rows


def world_inverse_inertia(inv_inertia_body: np.ndarray, body_rot: np.ndarray) -> np.ndarray:
    """I_world⁻¹ = R I_body⁻¹ Rᵀ, (nb,3,3)."""
    return body_rot @ inv_inertia_body @ np.swapaxes(body_rot, 1, 2)


def row_response(
    rows: Rows, inv_mass: np.ndarray, inv_inertia_world: np.ndarray, h: float
) -> tuple[np.ndarray, np.ndarray]:
    """(resp_a, resp_b), each (n,6): velocity change of each body per unit row force."""
    m = np.append(inv_mass, 0.0)
    inertia = np.concatenate((inv_inertia_world, np.zeros((1, 3, 3))), axis=0)

    def one(body: np.ndarray, jac: np.ndarray) -> np.ndarray:
        lin = m[body][:, None] * jac[:, :3]
        ang = np.einsum("nij,nj->ni", inertia[body], jac[:, 3:])
        return h * np.concatenate((lin, ang), axis=1)

    return one(rows.body_a, rows.jac_a), one(rows.body_b, rows.jac_b)


def regularize(rows: Rows, resp: tuple[np.ndarray, np.ndarray], eps: float) -> Rows:
    """Rows with compliance ε·A_ii on every row that has none (see Options.regularization)."""
    if eps <= 0.0 or len(rows) == 0:
        return rows
    diag = np.einsum("ni,ni->n", rows.jac_a, resp[0]) + np.einsum("ni,ni->n", rows.jac_b, resp[1])
    return replace(rows, comp=np.where(rows.comp > 0.0, rows.comp, eps * diag))


def dense_blocks(rows: Rows, block_a: np.ndarray, block_b: np.ndarray, nbody: int) -> np.ndarray:
    """Dense (n, 6·nbody) matrix with each row's two (6,) blocks at its bodies' columns.

    With the Jacobian blocks it is J; with the response blocks, (h M⁻¹ Jᵀ)ᵀ.
    Static bodies (-1) are dropped.
    """
    n = len(rows)
    out = np.zeros((n, 6 * nbody + 6))
    idx = np.arange(n)[:, None]
    for body, block in ((rows.body_a, block_a), (rows.body_b, block_b)):
        cols = 6 * np.where(body < 0, nbody, body)[:, None] + np.arange(6)
        out[idx, cols] += block
    return out[:, : 6 * nbody]


def dense_matrix(rows: Rows, resp: tuple[np.ndarray, np.ndarray], nbody: int) -> tuple:
    """(A, J): A = h J M⁻¹ Jᵀ (n, n) and the dense Jacobian J (n, 6·nbody)."""
    jac = dense_blocks(rows, rows.jac_a, rows.jac_b, nbody)
    a = jac @ dense_blocks(rows, resp[0], resp[1], nbody).T
    return 0.5 * (a + a.T), jac


def dense_system(
    rows: Rows, resp: tuple[np.ndarray, np.ndarray], vel_free: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(Q, c) with Q = A + diag(comp) and c = J v_free + bias: r = Qλ + c."""
    a, jac = dense_matrix(rows, resp, len(vel_free))
    return a + np.diag(rows.comp), jac @ vel_free.reshape(-1) + rows.bias
