"""Pins (solver.rows.pin) against independent values: the static force and moment balance of a
held chain, the exact free-fall momentum after unpinning, the weight a force limit must carry,
and a fixed root (the same step without a pin).

Every tolerance is ~5× the error measured on this machine (the measured value is beside it).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from rigbuild import chain, rheology

from solver import quat
from solver.engine import Engine
from solver.model import build_model
from solver.rows.grip import Pointer, make_coupling
from solver.rows.pin import make_pin, retarget
from solver.state import StepInput, initial_state

H = 0.005
GRIP_LIMIT = 2.0  # N per row: the grip pulls with exactly this on each world axis


def pinned_point(state, pin) -> np.ndarray:
    """Where the pin's point of its bone is (world)."""
    return state.body_pos[pin.bone] + quat.rotate(state.body_quat[pin.bone], pin.point)


def held_chain(steps: int):
    """A free 3-link chain (elastic joints) whose first link is pinned whole at its head,
    its last link's tail gripped towards a pointer 1.7 m away: every grip row sits at its
    limit, so the grip's force is known, GRIP_LIMIT on each axis.  Returns (model, state,
    report, pin, coupling, the pinned point's largest distance from its target, the
    engine that stepped it)."""
    model = build_model(chain(3, H, root_mode="free", rheo=rheology(5.0, 0.5, np.inf)))
    engine, state = Engine(model), initial_state(model)
    pin = make_pin(state, 0, model.bone_head0[0] - model.body_pos0[0], orient=True)
    tip = model.bone_tail0[2]
    still = Pointer(tip, quat.IDENTITY.copy(), np.zeros(3), np.zeros(3))
    grip = make_coupling(
        state, still, 2, tip, stiffness=2000.0, damping=40.0, rot_stiffness=1.0,
        rot_damping=0.1, force_limit=GRIP_LIMIT, torque_limit=1.0, position_only=True,
    )  # fmt: skip
    far = Pointer(tip + 1.0, quat.IDENTITY.copy(), np.zeros(3), np.zeros(3))
    inp = StepInput(pointer=far, coupling=grip, pins=(pin,))
    drift = 0.0
    for _ in range(steps):
        state, report = engine.step(state, inp)
        drift = max(drift, float(np.linalg.norm(pinned_point(state, pin) - pin.target)))
    return model, state, report, pin, grip, drift, engine


def test_a_pinned_point_holds_and_carries_the_chains_weight_and_the_grips_pull():
    model, state, report, pin, grip, drift, _ = held_chain(800)
    # the chain swings up towards the pointer and settles while the pin holds
    assert drift < 2.5e-6  # measured 5.3e-7 m over the 4 s
    assert np.max(np.abs(state.body_vel)) < 1e-10  # at rest: a static balance holds
    assert np.array_equal(report.grip_force, [GRIP_LIMIT] * 3)
    weight = model.body_mass.sum() * model.options.gravity
    expected = -(report.grip_force + weight)
    assert np.max(np.abs(report.pin_force[0] - expected)) < 3e-11  # measured 6.2e-12 N
    # moments about the pinned point: the pin's torque balances the grip's and gravity's
    arm_grip = state.body_pos[2] + quat.rotate(state.body_quat[2], grip.anchor) - pin.target
    moment = np.cross(arm_grip, report.grip_force)
    for b in range(3):
        moment += np.cross(
            state.body_pos[b] - pin.target, model.body_mass[b] * model.options.gravity
        )
    assert np.max(np.abs(report.pin_torque[0] + moment)) < 1.5e-8  # measured 2.9e-9 N·m
    assert not report.pin_slip[0]


def falling_block(limit_factor: float, steps: int = 200):
    """One free 1 kg link pinned at its centre of mass with a force limit of
    ``limit_factor`` × its weight, slipped pins moved to where the point is (retarget)."""
    model = build_model(chain(1, H, root_mode="free")).with_options(sleep=False)
    weight = model.body_mass[0] * 9.81
    engine, state = Engine(model), initial_state(model)
    pins = (make_pin(state, 0, force_limit=limit_factor * weight),)
    start = pins[0].target.copy()
    lifts, slips = [], []
    for _ in range(steps):
        state, report = engine.step(state, StepInput(pins=pins))
        lifts.append(report.pin_force[0, 1])
        slips.append(bool(report.pin_slip[0]))
        pins = retarget(pins, state, report.pin_slip)
    return weight, state, np.array(lifts), np.array(slips), pins, start


def test_below_its_limit_a_pin_holds_the_weight():
    weight, state, lifts, slips, _pins, start = falling_block(1.001)
    assert not slips.any()
    # measured 9.8e-6 N in the first steps (the 1e-6 regularisation's sag), 0 after step 20
    assert np.max(np.abs(lifts[20:] - weight)) < 1e-12
    assert np.linalg.norm(state.body_pos[0] - start) < 1.5e-9  # measured 3.1e-10 m


def test_above_its_limit_a_pin_slips_carrying_exactly_its_limit_and_never_snaps_back():
    limit_factor = 0.999
    weight, state, lifts, slips, pins, start = falling_block(limit_factor)
    assert slips.all()
    assert np.max(np.abs(lifts - limit_factor * weight)) < 1e-12  # the bound itself: 0
    # it slides down at (W − L)/m: v after 1 s = 0.001 g
    assert state.body_vel[0, 1] == pytest.approx(-(1 - limit_factor) * 9.81, rel=2e-13)  # 3.8e-14
    # a stronger pin from the slipped target holds there: no pull back to where it started
    engine = Engine(build_model(chain(1, H, root_mode="free")))
    held = (replace(pins[0], force_limit=2 * weight),)
    moved = held[0].target
    for _ in range(100):
        state, _ = engine.step(state, StepInput(pins=held))
    assert np.linalg.norm(state.body_pos[0] - moved) < 1.5e-9  # measured 3.1e-10 m
    assert start[1] - moved[1] > 4e-3  # it had slid 4.9 mm


def test_a_whole_bone_pin_on_a_free_root_is_a_fixed_root():
    rh = rheology(5.0, 0.5, 2.0)  # plastic joints: the chain droops 0.35 m under gravity
    fixed = build_model(chain(4, H, root_mode="fixed", rheo=rh))
    free = build_model(chain(4, H, root_mode="free", rheo=rh))
    a, b = initial_state(fixed), initial_state(free)
    step_fixed, step_free = Engine(fixed), Engine(free)
    pins = (make_pin(b, 0, orient=True),)
    err = 0.0
    for _ in range(400):
        a, _ = step_fixed.step(a)
        b, _ = step_free.step(b, StepInput(pins=pins))
        err = max(
            err, np.abs(a.body_pos - b.body_pos).max(), np.abs(a.body_quat - b.body_quat).max()
        )
    assert np.linalg.norm(a.body_pos[3] - fixed.body_pos0[3]) > 0.3
    assert err < 3e-7  # measured 6.3e-8 (m and quaternion units): the rows' 1e-6 regularisation


def test_unpinning_gives_no_kick_the_free_chain_falls_by_gravity_alone():
    model, state, _report, _pin, _grip, _, engine = held_chain(800)  # the same engine after
    momentum = model.body_mass @ state.body_vel
    after, _ = engine.step(state)  # unpinned and released at once
    gained = model.body_mass @ after.body_vel - momentum
    expected = model.body_mass.sum() * model.options.gravity * H
    assert np.max(np.abs(gained - expected)) < 1.5e-16  # measured 2.8e-17 kg·m/s (1 ulp)
    # no body jumps: measured 0.075 m/s, the links unbending as they start to fall (g·h = 0.049)
    assert np.max(np.abs(after.body_vel - state.body_vel)) < 2 * 9.81 * H


def test_the_in_place_stepper_reports_the_pins_as_the_step_does():
    model = build_model(chain(3, H, root_mode="free", rheo=rheology(5.0, 0.5, np.inf)))
    state = initial_state(model)
    pins = (make_pin(state, 0, orient=True), make_pin(state, 2, force_limit=4.0))
    engine, sim = Engine(model), Engine(model).stepper(state)
    for _ in range(50):
        state, report = engine.step(state, StepInput(pins=pins))
        kept = sim.step(StepInput(pins=pins))
        for name in ("pin_force", "pin_torque", "pin_slip"):
            assert np.array_equal(getattr(report, name), getattr(kept, name)), name
    assert np.array_equal(sim.state.body_pos, state.body_pos)
    assert report.pin_slip[1] and not report.pin_slip[0]  # the tip's 4 N gives
