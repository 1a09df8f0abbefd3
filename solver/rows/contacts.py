"""Contact rows: one normal row per contact point, and two friction rows when it has friction.

Normal row: w = n·(v_b + ω_b × r_b − v_a − ω_a × r_a) (separating > 0), λ ≥ 0.
With depth d (> 0 penetrating, < 0 a gap of −d):
    bias = −d/h                         for a gap (speculative: may close, not cross),
    bias = −erp·max(d − slop, 0)/h      when penetrating (push out beyond the slop).
Friction rows along t1, t2 ⊥ n, bounds ±μ·λ_n per row (Coulomb friction as a box,
as in the reference implementation); a frictionless contact (μ = 0) has none, since
rows held at ±0 would only cost the solver (its λ is exactly zero either way).  t1
follows the tangential relative velocity the step would produce without constraints
(so a block on a slope has one friction row along the slope and the box bound is the
exact Coulomb bound); at rest a fixed basis is used.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from solver import quat
from solver.collide.scene import Contacts
from solver.model import Model
from solver.rows.table import KIND_CONTACT, KIND_FRICTION, Rows, concat, make_rows, point_jacobians


def _point_velocity(vel: np.ndarray, body: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Velocity of world points rigidly attached to bodies (static = 0)."""
    v = np.vstack((vel, np.zeros((1, 6))))[body]
    return v[:, :3] + quat.cross(v[:, 3:], r)


def tangent_basis(normal: np.ndarray, slip: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(t1, t2) unit tangents; t1 along the tangential part of ``slip`` when it has one."""
    t = slip - np.einsum("ni,ni->n", slip, normal)[:, None] * normal
    norm = np.linalg.norm(t, axis=1)
    ref = np.where(np.abs(normal[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 0.0, 1.0]])
    fixed = quat.cross(normal, ref)
    fixed /= np.linalg.norm(fixed, axis=1, keepdims=True)
    t1 = np.where((norm > 1e-9)[:, None], t / np.maximum(norm, 1e-300)[:, None], fixed)
    return t1, quat.cross(normal, t1)


def contact_rows(
    model: Model,
    con: Contacts,
    body_pos: np.ndarray,
    vel_free: np.ndarray,
    velocity_a: np.ndarray | None = None,
) -> Rows:
    """Rows of all contacts: normals first (in contact order), then the friction pairs of
    those with friction (μ > 0).

    velocity_a (3,): velocity of a moving static side (the pointer); None = at rest.
    """
    opt = model.options
    h = opt.h
    nc = len(con.key)
    pos = np.vstack((body_pos, np.zeros((1, 3))))
    r_a = con.point - pos[con.body_a]
    r_b = con.point - pos[con.body_b]
    jac_a, jac_b = point_jacobians(con.normal, r_a, r_b)
    d = con.depth
    bias = np.where(d < 0.0, -d / h, -opt.contact_erp * np.maximum(d - opt.contact_slop, 0.0) / h)
    u = np.zeros(3) if velocity_a is None else velocity_a
    bias = bias - con.normal @ u
    normal = make_rows(
        KIND_CONTACT, con.key, con.body_a, con.body_b, jac_a, jac_b, lo=0.0, bias=bias
    )
    f = np.flatnonzero(con.friction > 0.0)  # the contacts with friction rows
    body_a, body_b, r_a, r_b = con.body_a[f], con.body_b[f], r_a[f], r_b[f]
    slip = _point_velocity(vel_free, body_b, r_b) - _point_velocity(vel_free, body_a, r_a) - u
    t1, t2 = tangent_basis(con.normal[f], slip)
    axes = np.stack((t1, t2), axis=1).reshape(-1, 3)
    fa, fb = point_jacobians(axes, np.repeat(r_a, 2, axis=0), np.repeat(r_b, 2, axis=0))
    friction = make_rows(
        KIND_FRICTION,
        2 * np.repeat(con.key[f], 2) + np.tile([0, 1], len(f)),
        np.repeat(body_a, 2),
        np.repeat(body_b, 2),
        fa,
        fb,
        mu=np.repeat(con.friction[f], 2),
        bias=-(axes @ u),
    )
    rows = concat([normal, friction])
    fric_of = np.concatenate((np.full(nc, -1), np.repeat(f, 2)))
    return replace(rows, fric_of=fric_of.astype(np.int64))
