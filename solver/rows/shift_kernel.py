"""Compiled velocity shift of a BDF2 stage's rows (solver.rows.shift's twin)."""

from __future__ import annotations

from solver.compiled.layout import Coupling
from solver.jit import kernel
from solver.rows.shift import GRIP_FORCE_ROWS
from solver.rows.table import KEY_SHIFT, KIND_FRICTION, KIND_GRIP, KIND_RHEOLOGY

_IDENT = (1 << KEY_SHIFT) - 1


@kernel(error_model="numpy", _nrt=False)
def shift_rows(rw, n, shift, joint_df, flows, cvec):
    """rw.bias[:n] += s·J ṽ (solver.rows.shift.velocity_share): shift (nb,6) ṽ, ω̃ per body;
    joint_df (nj,3): D_f; flows (nj,) bool: the joints on the three-element row at the
    start of the step; cvec: the grip's coupling (layout.Coupling)."""
    for i in range(n):
        kind = rw.kind[i]
        ident = rw.key[i] & _IDENT
        if kind == KIND_FRICTION:
            share = 1.0
        elif kind == KIND_RHEOLOGY:
            j = ident // 3
            share = 1.0 if flows[j] else joint_df[j, ident % 3] * rw.comp[i]
        elif kind == KIND_GRIP:
            damping = (
                cvec[Coupling.damping] if ident < GRIP_FORCE_ROWS else cvec[Coupling.rot_damping]
            )
            share = damping * rw.comp[i]
        else:
            continue
        wa = wb = 0.0
        a, b = rw.body_a[i], rw.body_b[i]
        for k in range(6):
            if a >= 0:
                wa += rw.jac_a[i, k] * shift[a, k]
            if b >= 0:
                wb += rw.jac_b[i, k] * shift[b, k]
        rw.bias[i] += share * (wa + wb)
