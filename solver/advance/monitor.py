"""Detection of numerical trouble after a step: non-finite state, runaway speed
(the symptom of an energy blow-up), and joints pulled apart."""

from __future__ import annotations

import numpy as np

from solver.errors import SimulationError
from solver.model import Model
from solver.observe import joint_gaps


def check_state(
    model: Model, step: int, time: float, pos: np.ndarray, q: np.ndarray, vel: np.ndarray
) -> None:
    """Raise SimulationError naming the step, time and worst bone when the new state is broken."""
    opt = model.options
    finite = np.isfinite(pos).all(1) & np.isfinite(q).all(1) & np.isfinite(vel).all(1)
    if not finite.all():
        body = _first_broken(model, ~finite)
        raise SimulationError(
            "state became non-finite (NaN or infinity)", step, time, model.body_names[body]
        )
    speed = np.linalg.norm(vel[:, :3], axis=1)
    spin = np.linalg.norm(vel[:, 3:], axis=1)
    excess = np.maximum(speed / opt.max_speed, spin / opt.max_angular_speed)
    if excess.max(initial=0.0) > 1.0:
        body = int(np.argmax(excess))
        raise SimulationError(
            f"energy blow-up: speed {speed[body]:.3g} m/s, spin {spin[body]:.3g} rad/s "
            f"(limits {opt.max_speed:g} m/s, {opt.max_angular_speed:g} rad/s)",
            step,
            time,
            model.body_names[body],
        )
    if model.njoint:
        gaps = joint_gaps(model, pos, q)
        j = int(np.argmax(gaps))
        if gaps[j] > opt.max_joint_gap:
            raise SimulationError(
                f"joint pulled apart: anchors {gaps[j]:.3g} m apart "
                f"(limit {opt.max_joint_gap:g} m)",
                step,
                time,
                model.joint_names[j],
            )


def _first_broken(model: Model, broken: np.ndarray) -> int:
    """The first broken movable body; a fixed body only when no movable one is broken
    (an infinite force turns a fixed root's 0·∞ into NaN too, but the cause is elsewhere)."""
    movable = broken & (model.body_inv_mass > 0.0)
    return int(np.flatnonzero(movable if movable.any() else broken)[0])
