"""The uniform row table every constraint kind emits.

A row i couples body ``body_a[i]`` and body ``body_b[i]`` (-1 = the static world)
through Jacobian blocks jac_a, jac_b (6,) = (linear, angular), world frame:

    w_i = jac_a · (v_a, ω_a) + jac_b · (v_b, ω_b)              (row velocity)

and solves, with the row force λ_i (N or N·m) applying the impulse h·Jᵀλ,

    r_i = w_i[t+1] + comp_i·λ_i + bias_i,   lo_i ≤ λ_i ≤ hi_i,
    r_i = 0 if lo < λ < hi,   r_i ≥ 0 if λ = lo,   r_i ≤ 0 if λ = hi.

Friction rows have ``fric_of`` = index of their normal row and bounds
±mu·λ_normal (set by the solver); other rows have fric_of = -1.
``key`` is a stable int64 identity used to carry forces to the next step
(warm start); ``kind`` says where the row came from, for statistics only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from solver import quat

KIND_JOINT, KIND_RHEOLOGY, KIND_LIMIT, KIND_CONTACT, KIND_FRICTION, KIND_GRIP, KIND_PIN = range(7)
# Key layout: kind in the top bits, then up to 2**40 per-kind identities.
KEY_SHIFT = 40


@dataclass(frozen=True)
class Rows:
    """A row table; all arrays have the row count n as first dimension."""

    body_a: np.ndarray  # (n,) int64
    body_b: np.ndarray  # (n,) int64
    jac_a: np.ndarray  # (n,6)
    jac_b: np.ndarray  # (n,6)
    lo: np.ndarray  # (n,)
    hi: np.ndarray  # (n,)
    comp: np.ndarray  # (n,)
    bias: np.ndarray  # (n,)
    fric_of: np.ndarray  # (n,) int64
    mu: np.ndarray  # (n,)
    key: np.ndarray  # (n,) int64
    kind: np.ndarray  # (n,) int8

    def __len__(self) -> int:
        return len(self.key)

    @property
    def bilateral(self) -> bool:
        """True when every row may push both ways (lo < 0 < hi) and none is friction:
        the direct solve applies, valid when its forces stay within the bounds."""
        return bool(np.all(self.lo < 0.0) and np.all(self.hi > 0.0) and np.all(self.fric_of < 0))

    @property
    def equality_only(self) -> bool:
        """True when no row has a finite bound: the problem is a linear system."""
        return bool(np.all(np.isinf(self.lo)) and np.all(np.isinf(self.hi)))


def make_rows(
    kind: int,
    ident: np.ndarray,
    body_a: np.ndarray,
    body_b: np.ndarray,
    jac_a: np.ndarray,
    jac_b: np.ndarray,
    *,
    lo: float | np.ndarray = -np.inf,
    hi: float | np.ndarray = np.inf,
    comp: float | np.ndarray = 0.0,
    bias: float | np.ndarray = 0.0,
    fric_of: np.ndarray | None = None,
    mu: float | np.ndarray = 0.0,
) -> Rows:
    """A block of rows of one kind; scalars broadcast over the block."""
    n = len(ident)

    def full(x, dtype=float):
        return np.broadcast_to(np.asarray(x, dtype=dtype), (n,)).copy()

    return Rows(
        body_a=full(body_a, np.int64),
        body_b=full(body_b, np.int64),
        jac_a=np.asarray(jac_a, dtype=float).reshape(n, 6),
        jac_b=np.asarray(jac_b, dtype=float).reshape(n, 6),
        lo=full(lo),
        hi=full(hi),
        comp=full(comp),
        bias=full(bias),
        fric_of=full(-1 if fric_of is None else fric_of, np.int64),
        mu=full(mu),
        key=(np.int64(kind) << KEY_SHIFT) + np.asarray(ident, dtype=np.int64),
        kind=np.full(n, kind, dtype=np.int8),
    )


def concat(blocks: list[Rows]) -> Rows:
    """Stack row blocks in order; friction indices are shifted to the new positions."""
    blocks = [b for b in blocks if len(b) > 0]
    if not blocks:
        return make_rows(
            0, np.zeros(0), np.zeros(0), np.zeros(0), np.zeros((0, 6)), np.zeros((0, 6))
        )
    offsets = np.cumsum([0] + [len(b) for b in blocks[:-1]])
    fric = [
        np.where(b.fric_of >= 0, b.fric_of + o, -1) for b, o in zip(blocks, offsets, strict=True)
    ]
    fields = {
        name: np.concatenate([getattr(b, name) for b in blocks])
        for name in Rows.__dataclass_fields__
        if name != "fric_of"
    }
    return Rows(fric_of=np.concatenate(fric), **fields)


def angular_jacobians(axes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Jacobian blocks of rows measuring (ω_b − ω_a)·axis, axes (n,3) world."""
    n = len(axes)
    jac_b = np.zeros((n, 6))
    jac_b[:, 3:] = axes
    jac_a = -jac_b
    return jac_a, jac_b


def point_jacobians(
    axes: np.ndarray, r_a: np.ndarray, r_b: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Jacobian blocks of rows measuring the relative velocity of a point along axes.

    w = axis·(v_b + ω_b × r_b − v_a − ω_a × r_a), with r the point relative to each
    body's centre of mass (world); e·(ω × r) = ω·(r × e).
    """
    jac_b = np.concatenate((axes, quat.cross(r_b, axes)), axis=1)
    jac_a = -np.concatenate((axes, quat.cross(r_a, axes)), axis=1)
    return jac_a, jac_b


def take_rows(rows: Rows, keep: np.ndarray) -> Rows:
    """The rows ``keep`` (friction rows' normal indices renumbered)."""
    new_index = np.cumsum(keep) - 1
    fric = np.where(rows.fric_of >= 0, new_index[np.maximum(rows.fric_of, 0)], -1)
    fields = {f: getattr(rows, f)[keep] for f in Rows.__dataclass_fields__ if f != "fric_of"}
    return Rows(fric_of=fric[keep], **fields)
