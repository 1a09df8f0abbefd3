"""When an island falls asleep: the rest timer against its recursion, at its thresholds.

The rule (solver.advance.sleep, Options): after each step an awake island whose every body
moved slower than ``sleep_speed`` (m/s) and spun slower than ``sleep_spin`` (rad/s)
advances its timer by h, any faster body resets it to 0, and the island falls asleep
once the timer reaches ``sleep_time``.  For an island kept at a constant speed the step
it falls asleep at is therefore the first n with h + h + … (n terms, summed here in that
order) ≥ sleep_time, or never.  Checked on a weightless chain drifting at constant
velocity and a ball spinning at a constant rate, just below and just above each
threshold, on both engines.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from rigbuild import chain

from solver.engine import Engine
from solver.model import build_model
from solver.state import initial_state

H = 0.005
SPEED, SPIN, TIME = 5e-4, 5e-3, 0.2  # the defaults of solver.model.Options


def first_asleep(
    engine: str, vel: np.ndarray, omega: np.ndarray, steps: int, links: int = 3
) -> int | None:
    """The step (1-based) after which every body is asleep, or None."""
    spec = chain(links, H, root_mode="free", gravity=(0.0, 0.0, 0.0), shape="sphere", radius=0.03)
    model = build_model(spec).with_options(
        engine=engine, sleep=True, sleep_speed=SPEED, sleep_spin=SPIN, sleep_time=TIME
    )
    n = model.nbody
    state = replace(initial_state(model), body_vel=np.tile(vel, (n, 1)),
                    body_omega=np.tile(omega, (n, 1)))  # fmt: skip
    stepper = Engine(model).stepper(state)
    for k in range(1, steps + 1):
        stepper.advance()
        if stepper.view().body_asleep.all():
            return k
    return None


def recursion() -> int:
    timer, n = 0.0, 0
    while timer < TIME:
        timer += H
        n += 1
    return n


@pytest.mark.parametrize("engine", ["numpy", "compiled"])
def test_an_island_falls_asleep_when_its_timer_reaches_sleep_time(engine):
    # a rigid drift (every body the same velocity, no spin: the joints carry nothing)
    below = np.array([0.0, 0.0, 0.98 * SPEED])
    assert first_asleep(engine, below, np.zeros(3), 60) == recursion()
    spin = np.array([0.0, 0.98 * SPIN, 0.0])  # a ball's spin is constant, torque-free
    assert first_asleep(engine, np.zeros(3), spin, 60, links=1) == recursion()


@pytest.mark.parametrize("engine", ["numpy", "compiled"])
def test_an_island_moving_at_its_thresholds_stays_awake(engine):
    above = np.array([0.0, 0.0, 1.02 * SPEED])
    assert first_asleep(engine, above, np.zeros(3), 60) is None
    spin = np.array([0.0, 1.02 * SPIN, 0.0])
    assert first_asleep(engine, np.zeros(3), spin, 60, links=1) is None
