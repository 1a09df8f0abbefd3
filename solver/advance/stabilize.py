"""Post-stabilisation of ball-joint anchors (a position projection after the step).

Velocity-level rows keep the anchors' relative velocity at zero, but the
rotation's curvature opens a gap of O((ωh)²·r) per step.  After integrating,
the gap C (3 per joint) is removed by the mass-weighted smallest correction:

    J Δ = −C,   Δ = M⁻¹ Jᵀ μ   ⇒   (J M⁻¹ Jᵀ) μ = −C,

Δ = (Δx, Δθ) per body, applied as x += Δx, q ← exp(Δθ) ⊗ q.  This changes
positions only (not velocities), so it adds no energy.  It is skipped when every
gap is already below ``tol`` and repeated (Newton-like) while it is not.  Moving
positions changes the orbital angular momentum Σ x × p, so the projection (which also
bleeds a little energy, since the gaps it closes always open outwards) is a safety net
for violent motion, not part of ordinary steps: below ``tol`` the step conserves
momentum exactly.

The trigger (``projection_tol``) is 0.1 mm up to PROJECT_STEP (5 ms, the rigs' step) and
grows with h above it (0.4 mm at 20 ms, 1 mm at 50 ms).  The gap a step leaves grows as
(ωh)²·r, so a fixed 0.1 mm fired on a quarter of the steps of ordinary motion at 10–40 ms
(the released chains and doll of ``puppetcli bench --accuracy``), moving positions without
their velocities: against it the scaled trigger takes 7–22 % less time there, with the bent
chain's error 4.31 → 3.55 mm at 10 ms (docs/integrators.md).  Velocity-level drift
correction (Options.joint_erp) still pulls every gap back each step.
"""

from __future__ import annotations

import numpy as np

from solver import quat
from solver.jit import kernel
from solver.model import Model
from solver.observe import joint_gaps
from solver.rows.joints import anchor_rows, joint_frames
from solver.rows.table import Rows
from solver.solve.response import dense_matrix, row_response, world_inverse_inertia


def _subset(rows: Rows, keep: np.ndarray) -> Rows:
    """The anchor rows ``keep`` (no friction rows among them)."""
    return Rows(**{f: getattr(rows, f)[keep] for f in Rows.__dataclass_fields__})


PROJECT_TOL, PROJECT_STEP = 1e-4, 5e-3  # m, s: the trigger, and the step up to which it holds


@kernel(error_model="numpy")
def projection_tol(h):
    """The anchor gap (m) above which a step of h seconds projects (module docstring):
    PROJECT_TOL up to PROJECT_STEP, growing in proportion to h above it."""
    return PROJECT_TOL * max(1.0, h / PROJECT_STEP)


def project_joints(
    model: Model,
    pos: np.ndarray,
    q: np.ndarray,
    tol: float | None = None,
    rounds: int = 3,
    asleep: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Positions and orientations with the joint anchors pulled together where some gap
    exceeds ``tol`` (``projection_tol`` of the model's step when None); the joints of
    sleeping bodies (``asleep`` (nb,) bool: solver.advance.sleep) are left as they are."""
    import scipy.linalg  # on use: the compiled step never needs it, and it costs ~0.3 s to import

    tol = projection_tol(model.options.h) if tol is None else tol

    if model.njoint == 0:
        return pos, q
    nb = model.nbody
    awake = np.ones(model.njoint, dtype=bool) if asleep is None else ~asleep[model.joint_bone]
    if not awake.any():
        return pos, q
    rows3 = np.repeat(awake, 3)
    for _ in range(rounds):
        if joint_gaps(model, pos, q)[awake].max() <= tol:
            break
        rot = quat.matrix(q)
        fr = joint_frames(model, pos, q, rot)
        rows = anchor_rows(model.with_options(joint_erp=1.0), fr, 1.0)
        rows = _subset(rows, rows3)
        resp = row_response(
            rows, model.body_inv_mass, world_inverse_inertia(model.body_inv_inertia, rot), 1.0
        )
        a, _ = dense_matrix(rows, resp, nb)
        gap = (fr.anchor_child - fr.anchor_parent).reshape(-1)[rows3]
        mu = scipy.linalg.cho_solve(scipy.linalg.cho_factor(a + 1e-14 * np.eye(len(a))), -gap)
        delta = np.zeros((nb + 1, 6))
        np.add.at(delta, rows.body_a, resp[0] * mu[:, None])
        np.add.at(delta, rows.body_b, resp[1] * mu[:, None])
        pos = pos + delta[:nb, :3]
        q = quat.normalize(quat.mul(quat.exp(delta[:nb, 3:]), q))
    return pos, q
