"""A small swing of a bone hanging from a ball joint: its period against the closed form.

A rigid body of mass m hanging from a frictionless pivot at distance d above its centre
of mass, with moment of inertia I_c about the swing axis through that centre, swings
with period T = 2π √((I_c + m d²)/(m g d)) · (1 + θ₀²/16 + 11 θ₀⁴/3072 + …) for an
amplitude θ₀.  The bone here is a capsule hanging straight down, so I_c is the
capsule's moment about an axis across it, integrated over the solid
(test_massprops.revolution), not taken from the model.  A 0.5 % error in gravity moves
the period by 0.25 %, one in the mass by 0.18 % (this bone), far beyond the tolerance.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from test_massprops import capsule_profile, revolution

from solver.engine import Engine
from solver.model import build_model
from solver.spec import BoneSpec, RigSpec, ShapeSpec, SolverSpec
from solver.state import initial_state

G, MASS, RADIUS, LENGTH = 9.81, 0.8, 0.02, 0.3
PIVOT = np.array([0.0, 1.0, 0.0])
THETA0 = 0.03  # rad
H = 0.002


def closed_form_period() -> float:
    volume, _, perp = revolution(capsule_profile(RADIUS, LENGTH), LENGTH / 2 + RADIUS)
    inertia_c = perp * MASS / volume
    d = LENGTH / 2
    small = 2 * math.pi * math.sqrt((inertia_c + MASS * d * d) / (MASS * G * d))
    return small * (1 + THETA0**2 / 16 + 11 * THETA0**4 / 3072)


def swing_angles(engine: str, steps: int) -> np.ndarray:
    """The bone's angle from the vertical about z (rad) after each step."""
    bone = BoneSpec(
        name="bob", parent=None, head=PIVOT, tail=PIVOT - [0.0, LENGTH, 0.0],
        shape=ShapeSpec("capsule", radius=RADIUS), mass=MASS,
    )  # fmt: skip
    spec = RigSpec(
        name="pendulum", bones=(bone,), root_mode="ball", gravity=np.array([0.0, -G, 0.0]),
        solver=SolverSpec(h=H),
    )  # fmt: skip
    model = build_model(spec).with_options(engine=engine, sleep=False)
    state = initial_state(model)
    tilt = Rotation.from_rotvec([0.0, 0.0, THETA0])
    pos = PIVOT + tilt.apply(state.body_pos[0] - PIVOT)
    state = replace(
        state,
        body_pos=pos[None, :],
        body_quat=(tilt * Rotation.from_quat(state.body_quat[0], scalar_first=True)).as_quat(
            scalar_first=True
        )[None, :],
    )
    stepper = Engine(model).stepper(state)
    angles = np.empty(steps)
    for k in range(steps):
        stepper.advance()
        down = stepper.view().body_pos[0] - PIVOT
        angles[k] = math.atan2(down[0], -down[1])
    return angles


def measured_period(angles: np.ndarray) -> float:
    """Mean time between downward zero crossings, each found by linear interpolation."""
    t = H * np.arange(1, len(angles) + 1)
    i = np.flatnonzero((angles[:-1] > 0.0) & (angles[1:] <= 0.0))
    crossings = t[i] + H * angles[i] / (angles[i] - angles[i + 1])
    return float(np.mean(np.diff(crossings)))


@pytest.mark.parametrize("engine", ["numpy", "compiled"])
def test_small_swing_has_the_closed_form_period(engine):
    expected = closed_form_period()
    angles = swing_angles(engine, int(2.3 * expected / H))
    # it swings undamped: the amplitude is kept to 2.3e-5 (measured, both engines)
    assert np.abs(angles).max() == pytest.approx(THETA0, rel=1e-4)
    # measured: 7.8e-6 relative at h = 2 ms on both engines
    assert measured_period(angles) == pytest.approx(expected, rel=4e-5)
