"""The velocity shift of a BDF2 stage's rows (solver.advance.bdf2).

A BDF2 stage solves for δv = v[t+1] − ṽ, linearised at the predicted end pose x̃, so a
row's velocity at t+1 is w = J δv + w̃ with w̃ = J ṽ, and its position at t+1 is
C(x̃) + γ J δv.  The row builders give each row its law in terms of the stage's unknown
as if w̃ were zero; what w̃ adds to a row's bias is its *velocity share* s·w̃:

- a row on position only (a joint anchor, a contact's normal, a limit): s = 0;
- a Voigt row (an elastic joint, the grip), λ = −K (e + γ J δv) − D (J δv + w̃ − u):
  J δv + C λ + β + D·C·w̃ = 0 with C = 1/(D + K γ), so s = D·C;
- a friction row (w = 0) and a three-element row (w + Cλ + D q̂_sf = 0, w the joint's
  whole velocity): s = 1.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from solver.model import Model
from solver.rows.joints import flowing
from solver.rows.table import KEY_SHIFT, KIND_FRICTION, KIND_GRIP, KIND_RHEOLOGY, Rows

GRIP_FORCE_ROWS = 3
"""A grip's rows are identities 0–2 (force, damper ``damping``) then 3–5 (torque,
``rot_damping``)."""


def velocity_share(model: Model, rows: Rows, yielded: np.ndarray, coupling=None) -> np.ndarray:
    """(n,) each row's velocity share s (module docstring); yielded (nj,) the joints'
    flags at the start of the step, coupling: the grip (solver.rows.grip.Coupling)."""
    ident = rows.key & ((1 << KEY_SHIFT) - 1)
    share = np.zeros(len(rows))
    share[rows.kind == KIND_FRICTION] = 1.0
    rheo = np.flatnonzero(rows.kind == KIND_RHEOLOGY)
    if len(rheo):
        joint, axis = ident[rheo] // 3, ident[rheo] % 3
        flow = flowing(model, yielded)[joint]
        share[rheo] = np.where(flow, 1.0, model.joint_df[joint, axis] * rows.comp[rheo])
    grip = np.flatnonzero(rows.kind == KIND_GRIP)
    if len(grip):
        damping = np.where(ident[grip] < GRIP_FORCE_ROWS, coupling.damping, coupling.rot_damping)
        share[grip] = damping * rows.comp[grip]
    return share


def shifted(rows: Rows, share: np.ndarray, shift: np.ndarray) -> Rows:
    """``rows`` with bias + s·J ṽ; shift (nb,6): ṽ, ω̃ per body (the world: zero)."""
    ext = np.vstack((shift, np.zeros((1, 6))))
    w = np.einsum("ni,ni->n", rows.jac_a, ext[rows.body_a]) + np.einsum(
        "ni,ni->n", rows.jac_b, ext[rows.body_b]
    )
    return replace(rows, bias=rows.bias + share * w)
