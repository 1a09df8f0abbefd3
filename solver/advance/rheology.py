"""The rheology update after the solve (digest §4.4, yield §2.6)."""

from __future__ import annotations

import numpy as np

from solver import quat
from solver.model import Model
from solver.observe import relative_rotations
from solver.rows.compliance import three_element_update
from solver.rows.joints import (
    elastic_deflection,
    flowing,
)
from solver.rows.table import KIND_RHEOLOGY, Rows
from solver.state import State


def rheology_update(
    model: Model, state: State, rows: Rows, vel: np.ndarray, lam: np.ndarray,
    rheo_joint: np.ndarray, body_quat: np.ndarray,
) -> dict:  # fmt: skip
    """q_sf, yield flags, anchors and torques after the solve (digest §4.4, yield §2.6)."""
    h = model.options.h
    nj = model.njoint
    sel = rows.kind == KIND_RHEOLOGY
    torque = np.zeros((nj, 3))
    w = np.zeros((nj, 3))
    if sel.any():
        vel_ext = np.vstack((vel, np.zeros((1, 6))))
        w_rows = np.einsum("ni,ni->n", rows.jac_a[sel], vel_ext[rows.body_a[sel]]) + np.einsum(
            "ni,ni->n", rows.jac_b[sel], vel_ext[rows.body_b[sel]]
        )
        j = rheo_joint[::3]
        torque[j] = lam[sel].reshape(-1, 3)
        w[j] = w_rows.reshape(-1, 3)
    alpha = h / (model.options.yield_filter_time + h)
    avg = state.joint_torque_avg + alpha * (np.linalg.norm(torque, axis=1) - state.joint_torque_avg)
    flow = flowing(model, state.joint_yielded) & model.joint_rheology
    q_sf = state.joint_q_sf.copy()
    if flow.any():
        dd = model.joint_dd[flow]
        q_sf[flow] = three_element_update(
            model.joint_kf[flow], model.joint_df[flow], dd, q_sf[flow], w[flow], h
        )
    can_yield = np.isfinite(model.joint_yield) & np.all(np.isfinite(model.joint_dd), axis=1)
    yielded = state.joint_yielded.copy()
    q_rel = relative_rotations(model, body_quat)
    anchor = state.joint_anchor.copy()
    unyield = can_yield & yielded & (avg < model.joint_yield)
    anchor[unyield] = quat.mul(quat.exp(-q_sf[unyield]), q_rel[unyield])
    yielded = np.where(can_yield, np.where(yielded, ~unyield, avg > model.joint_yield), False)
    elastic = ~flowing(model, yielded) & model.joint_rheology
    q_sf[elastic] = elastic_deflection(q_rel[elastic], anchor[elastic])
    return dict(
        joint_q_sf=q_sf,
        joint_yielded=yielded,
        joint_anchor=anchor,
        joint_torque_avg=avg,
        joint_torque=torque,
    )
