"""Contacts with Coulomb friction against closed-form expectations."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from solver.engine import Engine
from solver.model import build_model
from solver.spec import BoneSpec, GroundSpec, RigSpec, ShapeSpec, SolverSpec
from solver.state import StepInput, initial_state

G = 9.81


def free_body(shape: ShapeSpec, head, tail, gravity, friction: float, h: float) -> RigSpec:
    bone = BoneSpec(
        name="body",
        parent=None,
        head=np.array(head, dtype=float),
        tail=np.array(tail, dtype=float),
        shape=shape,
        mass=2.0,
    )
    return RigSpec(
        name="contact",
        bones=(bone,),
        root_mode="free",
        gravity=np.array(gravity, dtype=float),
        ground=GroundSpec(height=0.0, friction=friction),
        bone_friction=friction,
        solver=SolverSpec(h=h),
    )


def run(spec: RigSpec, seconds: float, engine: str = "numpy"):
    """(the stepper after ``seconds``, the body's position after every step)."""
    model = build_model(spec).with_options(engine=engine)
    stepper = Engine(model).stepper(initial_state(model))
    trail = []
    for _ in range(round(seconds / model.options.h)):
        stepper.advance()
        trail.append(stepper.view().body_pos[0].copy())
    return stepper, np.array(trail)


# A capsule resting on the ground sinks 3.3e-9, 1.6e-8 and 7.3e-8 m at h = 1, 5, 20 ms
# (measured, both engines): the contact rows hold it exactly but for the 1e-6
# regularisation.
SINK_TOLERANCE = 3.7e-7  # 5× the worst


@pytest.mark.parametrize("engine", ["numpy", "compiled"])
@pytest.mark.parametrize("h", [0.001, 0.005, 0.02])
def test_capsule_resting_on_the_ground_sinks_less_than_tolerance(h, engine):
    r = 0.05
    spec = free_body(
        ShapeSpec("capsule", radius=r),
        [0.0, r + 0.001, 0.0],
        [0.4, r + 0.001, 0.0],
        [0.0, -G, 0.0],
        0.8,
        h,
    )
    stepper, trail = run(spec, 2.0, engine)
    state = stepper.state
    bottom = trail[len(trail) // 2 :, 1] - r
    assert -bottom.min() < SINK_TOLERANCE
    # At rest, not bouncing: measured exactly still (asleep) at every h, on both engines.
    assert not state.body_vel.any() and not state.body_omega.any()


@pytest.mark.parametrize("engine", ["numpy", "compiled"])
@pytest.mark.parametrize("slop", [0.0, 0.0005, 0.001])
def test_a_capsule_started_in_the_ground_is_pushed_out_to_the_slop(slop, engine):
    # Started d0 = 2 mm deep, the contact row removes contact_erp = 20 % of the depth beyond
    # the slop each step (its bias), whatever gravity does: after one step
    # s + 0.8 (d0 − s), and at rest exactly the slop (solver: contact_slop).
    r, d0 = 0.05, 0.002
    spec = free_body(ShapeSpec("capsule", radius=r), [0.0, r - d0, 0.0], [0.4, r - d0, 0.0],
                     [0.0, -G, 0.0], 0.8, 0.005)  # fmt: skip
    spec = replace(spec, solver=SolverSpec(h=0.005, contact_slop=slop))
    _, trail = run(spec, 1.0, engine)
    depth = r - trail[:, 1]
    # measured: 1.0e-9 m off after the first step, 3.5e-9 m at rest (the regularisation)
    assert abs(depth[0] - (slop + 0.8 * (d0 - slop))) < 5e-9
    assert abs(depth[-1] - slop) < 1e-8


SLOPE_H = 0.002


def slope_run(tan_slope: float, mu: float, seconds: float, engine: str = "numpy"):
    """(slope angle, the slide along the slope (m) after every step from the first step's
    position, the last step's report)."""
    theta = np.arctan(tan_slope)
    gravity = [G * np.sin(theta), -G * np.cos(theta), 0.0]  # a slope rising towards -x
    spec = free_body(
        ShapeSpec("box", half_extents=(0.1, 0.05, 0.1)), [0, 0, 0], [0, 0.1, 0], gravity, mu,
        SLOPE_H,
    )  # fmt: skip
    stepper, trail = run(spec, seconds, engine)
    return theta, trail[:, 0] - trail[0, 0], stepper.report


def sliding(a: float, steps: int) -> np.ndarray:
    """The slide after steps 1 … ``steps`` of a body accelerating at a from rest under
    semi-implicit Euler at SLOPE_H: a·h²·k(k+1)/2 after k steps, counted from the first
    step's position, a·h²·(k(k+1)/2 − 1)."""
    k = np.arange(1, steps + 1)
    return a * SLOPE_H**2 * (k * (k + 1) / 2 - 1)


@pytest.mark.parametrize("engine", ["numpy", "compiled"])
def test_box_on_a_slope_sticks_below_the_friction_angle(engine):
    _, slide, _ = slope_run(0.4, 0.5, 1.0, engine)
    assert np.abs(slide).max() < 7e-9  # m: measured 1.6e-9, both (the 1e-6 regularisation)


@pytest.mark.parametrize("engine", ["numpy", "compiled"])
def test_box_on_a_slope_slides_above_the_friction_angle_at_the_coulomb_rate(engine):
    # Sliding, friction is μ·N exactly: the box accelerates at a = g(sin θ − μ cos θ) and
    # moves by ``sliding``'s recursion.  (The continuous ½at² differs by 0.2 % after 1 s:
    # the step's first-order error.)
    mu, t = 0.5, 1.0
    theta, slide, _ = slope_run(0.6, mu, t, engine)
    a = G * (np.sin(theta) - mu * np.cos(theta))
    assert np.abs(slide - sliding(a, len(slide))).max() < 6e-8  # m, of 0.42 m: 1.2e-8, both


@pytest.mark.parametrize("engine", ["numpy", "compiled"])
def test_a_resting_box_pushed_past_static_friction_slides_at_the_coulomb_rate(engine):
    # The box rests on flat ground (its contacts stick, solved exactly with nothing
    # iterated), then a horizontal push of 2μmg starts: on that step the sticking
    # contacts' friction would have to leave the pyramid, so they slide (iterated from
    # then on), and the box accelerates at a = (F − μmg)/m = μg along the recursion.
    mu, pushed = 0.5, 150
    spec = free_body(ShapeSpec("box", half_extents=(0.1, 0.05, 0.1)), [0, 0, 0], [0, 0.1, 0],
                     [0, -G, 0], mu, SLOPE_H)  # fmt: skip
    stepper, _ = run(spec, 0.1, engine)  # at rest
    assert stepper.report.iterations == 0  # sticking: nothing iterated
    start = stepper.view().body_pos[0, 0]
    push = StepInput(body_force=np.array([[2.0 * mu * 2.0 * G, 0.0, 0.0]]))  # m = 2 kg
    trail = []
    for _ in range(pushed):
        stepper.advance(push)
        trail.append(stepper.view().body_pos[0, 0] - start)
    a = mu * G
    exact = sliding(a, pushed) + a * SLOPE_H**2  # from the position before the push
    assert np.abs(np.array(trail) - exact).max() < 2e-12  # m, of 0.22 m: measured 4.1e-13, both


@pytest.mark.parametrize("engine", ["numpy", "compiled"])
def test_a_frictionless_contact_has_one_row_and_lets_the_box_slide_freely(engine):
    # μ = 0: the box slides at a = g sin θ, the same recursion as above with μ = 0, and
    # each contact point makes its normal row only (no friction rows held at ±0).
    theta, slide, report = slope_run(0.3, 0.0, 0.5, engine)
    assert np.abs(slide - sliding(G * np.sin(theta), len(slide))).max() < 3e-15  # m: 6.7e-16
    assert report.contacts == 4  # the box's bottom corners
    assert report.rows == report.contacts
