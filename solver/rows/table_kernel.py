"""Compiled row table (solver.rows.table's twin): the table's arrays, one row's entries,
the point and angular Jacobians.
"""

from __future__ import annotations

import math

import numpy as np

from solver.compiled.layout import Rows
from solver.jit import kernel
from solver.kin_kernel import (
    cross,
    neg,
)
from solver.rows.table import KEY_SHIFT

INF = math.inf


ZERO = (0.0, 0.0, 0.0)


AXES = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))


def row_arrays(rows) -> Rows:
    """A ``solver.rows.table.Rows`` table as the kernels take it (``rw``, layout.Rows)."""
    fields = {name: getattr(rows, name) for name in Rows._fields}
    return Rows(**fields | {"kind": rows.kind.astype(np.int64)})


@kernel(error_model="numpy")
def set_row(rw, i, kind, ident, a, b, ja, jb, lo, hi, comp, bias, fric_of, mu):
    """Row i; ja, jb = (linear, angular) 3-tuple pairs of the Jacobian blocks."""
    rw.body_a[i] = a
    rw.body_b[i] = b
    for k in range(3):
        rw.jac_a[i, k] = ja[0][k]
        rw.jac_a[i, 3 + k] = ja[1][k]
        rw.jac_b[i, k] = jb[0][k]
        rw.jac_b[i, 3 + k] = jb[1][k]
    rw.lo[i] = lo
    rw.hi[i] = hi
    rw.comp[i] = comp
    rw.bias[i] = bias
    rw.fric_of[i] = fric_of
    rw.mu[i] = mu
    rw.key[i] = (kind << KEY_SHIFT) + ident
    rw.kind[i] = kind


@kernel(error_model="numpy")
def point_jac(axis, r_a, r_b):
    """Blocks of w = axis·(v_b + ω_b × r_b − v_a − ω_a × r_a); e·(ω × r) = ω·(r × e)."""
    return (neg(axis), neg(cross(r_a, axis))), (axis, cross(r_b, axis))


@kernel(error_model="numpy")
def angular_jac(axis):
    """Blocks of w = axis·(ω_b − ω_a)."""
    return (neg(ZERO), neg(axis)), (ZERO, axis)


@kernel(error_model="numpy")
def null_rows(rw, n, kind, j, count):
    """``count`` empty rows in joint j's slots (its island sleeps: solver.advance.sleep): no
    bodies, no Jacobian, so no solver sees them; returns the next row."""
    for k in range(count):
        set_row(rw, n, kind, 3 * j + k, -1, -1, (ZERO, ZERO), (ZERO, ZERO), -INF, INF, 0.0,
                0.0, -1, 0.0)  # fmt: skip
        n += 1
    return n


@kernel(error_model="numpy")
def is_null(rw, i):
    """Row i is an empty slot (null_rows).  Not ``and``: an array read from a tuple in an
    and/or costs two uncancelled reference counts (~300 ns a call, numba 0.68)."""
    return (rw.body_a[i] < 0) & (rw.body_b[i] < 0)
