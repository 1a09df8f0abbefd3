"""Compiled rheology update after the solve (the numpy step's twin in
solver/advance/rheology.py): q_sf, yield, anchors, torques.
"""

from __future__ import annotations

from solver.compiled.layout import Opt
from solver.jit import kernel
from solver.kin_kernel import (
    neg,
    norm,
    put,
    qconj,
    qexp,
    qlog,
    qmul,
    quat_at,
    vec,
)
from solver.rows.joints_kernel import flowing, q_rel
from solver.rows.table import KIND_RHEOLOGY


@kernel(error_model="numpy", _nrt=False)
def rheology_update(rheo, opt, prev, rw, n, lam, vel, rheo_joint, quat, asleep, out, w):
    """q_sf, yield flags, anchors, torque filter and torques after the solve; the joints
    of sleeping bodies (asleep) keep their state (their torque reads 0: no rows).
    rheo: the model's joint parents, bones, K_f, D_f, D_d, has rheology, yield torque,
    plastic, finite yield (layout.Rheology); prev: the state's q_sf, yield flags, anchors,
    torque filter; w (nj, 3): scratch (the rheology rows'
    velocities)."""
    parent, bone, kf, df, dd, has, yield_, plastic, finite_yield = rheo
    q_sf0, yielded0, anchor0, avg0 = prev
    q_sf, yielded, anchor, avg, torque = out
    h = opt[Opt.h]
    nj, body_a, body_b, jac_a, jac_b, kind = (
        len(parent),
        rw.body_a,
        rw.body_b,
        rw.jac_a,
        rw.jac_b,
        rw.kind,
    )
    torque[:, :] = 0.0
    w[:, :] = 0.0
    slot = 0
    for i in range(n):
        if kind[i] != KIND_RHEOLOGY:
            continue
        j = rheo_joint[i]
        a, b = body_a[i], body_b[i]
        wa, wb = 0.0, 0.0
        for k in range(6):
            wa += jac_a[i, k] * vel[a, k] if a >= 0 else 0.0
            wb += jac_b[i, k] * vel[b, k] if b >= 0 else 0.0
        torque[j, slot % 3] = lam[i]
        w[j, slot % 3] = wa + wb
        slot += 1
    alpha = h / (opt[Opt.yield_filter_time] + h)
    for j in range(nj):
        tn = norm((torque[j, 0], torque[j, 1], torque[j, 2]))
        flow0 = flowing(plastic, finite_yield, yielded0, j)
        avg[j] = avg0[j] + alpha * (tn - avg0[j])
        for k in range(3):
            q_sf[j, k] = q_sf0[j, k]
            if flow0 and has[j]:
                t = dd[j, k] + df[j, k] + kf[j, k] * h
                q_sf[j, k] = ((dd[j, k] + df[j, k]) * q_sf0[j, k] + dd[j, k] * h * w[j, k]) / t
        for k in range(4):
            anchor[j, k] = anchor0[j, k]
        can_yield = finite_yield[j] and plastic[j]
        qr = q_rel(j, parent, bone, quat)
        unyield = can_yield and yielded0[j] and avg[j] < yield_[j]
        if unyield:
            qa = qmul(qexp(neg(vec(q_sf, j))), qr)
            for k in range(4):
                anchor[j, k] = qa[k]
        if can_yield:
            yielded[j] = (not unyield) if yielded0[j] else avg[j] > yield_[j]
        else:
            yielded[j] = False
        if has[j] and not flowing(plastic, finite_yield, yielded, j):
            put(q_sf, j, qlog(qmul(qr, qconj(quat_at(anchor, j)))))
        if asleep[bone[j]]:
            _freeze(j, q_sf0, yielded0, anchor0, avg0, q_sf, yielded, anchor, avg)


@kernel(error_model="numpy")
def _freeze(j, q_sf0, yielded0, anchor0, avg0, q_sf, yielded, anchor, avg):
    """Joint j keeps its rheology and yield state (its island sleeps)."""
    for k in range(3):
        q_sf[j, k] = q_sf0[j, k]
    for k in range(4):
        anchor[j, k] = anchor0[j, k]
    yielded[j], avg[j] = yielded0[j], avg0[j]
