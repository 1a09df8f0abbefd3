"""Sleeping (solver.advance.sleep): islands, falling asleep at rest, waking on every kind of
touch, and what sleeping changes against the same run awake."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from test_fast import lockstep

from puppetcli.bench.scenes import grip_inputs
from puppetcli.bench.solvers import doll_scenes
from puppetcli.bench.stress_scenes import free_bodies
from solver import quat
from solver.advance.sleep import body_islands
from solver.engine import Engine
from solver.rows.grip import Pointer
from solver.spec import ShapeSpec
from solver.state import StepInput, initial_state

DOLL = Path(__file__).resolve().parents[2] / "rigs" / "doll.yaml"
LEGS = ("thigh_l", "shin_l", "foot_l", "thigh_r", "shin_r", "foot_r")


@pytest.fixture(scope="module")
def doll():
    return doll_scenes()["doll"].with_options(h=0.005)


@pytest.fixture(scope="module")
def settled(doll):
    """The doll after 3 s left alone (every island asleep by then)."""
    doll_engine = Engine(doll)
    state = initial_state(doll)
    for _ in range(600):
        state, _ = doll_engine.step(state)
    return state


def names(model, mask) -> set[str]:
    return {model.body_names[b] for b in np.flatnonzero(mask)}


def test_the_clamped_hips_split_the_doll_into_three_islands(doll):
    island = body_islands(doll)
    hips = doll.body_names.index("hips")
    assert island[hips] == -1
    groups = {}
    for b, i in enumerate(island):
        groups.setdefault(int(i), set()).add(doll.body_names[b])
    assert groups[-1] == {"hips"}
    legs = [g for i, g in groups.items() if i >= 0 and g & set(LEGS)]
    assert sorted(map(sorted, legs)) == [["foot_l", "shin_l", "thigh_l"],
                                         ["foot_r", "shin_r", "thigh_r"]]  # fmt: skip
    assert len(groups) == 4  # the upper body is the fourth


def test_a_doll_left_alone_falls_asleep_frozen_at_rest(doll, settled):
    doll_engine = Engine(doll)
    assert settled.body_asleep[1:].all() and not settled.body_asleep[0]
    assert not settled.body_vel.any() and not settled.body_omega.any()
    later = settled
    for _ in range(20):
        later, report = doll_engine.step(later)
    assert np.array_equal(later.body_pos, settled.body_pos)
    assert np.array_equal(later.joint_q_sf, settled.joint_q_sf)
    assert report.rows == 0  # nothing left to solve


def test_a_grip_wakes_only_its_island(doll, settled):
    doll_engine = Engine(doll)
    inputs = grip_inputs(doll, 0.2, 10)
    state = settled
    for inp in inputs:
        state, _ = doll_engine.step(state, inp)
    assert names(doll, ~state.body_asleep) == names(doll, body_islands(doll) == body_islands(doll)[
        doll.body_names.index("forearm_l")]) | {"hips"}  # fmt: skip
    assert names(doll, state.body_asleep) == set(LEGS)


def test_a_push_wakes_the_pushed_island(doll, settled):
    doll_engine = Engine(doll)
    force = np.zeros((doll.nbody, 3))
    force[doll.body_names.index("shin_r")] = [5.0, 0.0, 0.0]
    state, _ = doll_engine.step(settled, StepInput(body_force=force))
    assert names(doll, ~state.body_asleep) == {"hips", "thigh_r", "shin_r", "foot_r"}


def test_a_free_pointer_near_a_shape_wakes_it(doll, settled):
    doll_engine = Engine(doll)
    foot = doll.body_names.index("foot_l")
    near = settled.body_pos[foot] + [0.0, 0.0, 0.08]
    ptr = Pointer(near, quat.IDENTITY, np.zeros(3), np.zeros(3), radius=0.02)
    state, _ = doll_engine.step(settled, StepInput(pointer=ptr))
    assert names(doll, ~state.body_asleep) == {"hips", "thigh_l", "shin_l", "foot_l"}
    far = Pointer(near + [0.0, 0.0, 1.0], quat.IDENTITY, np.zeros(3), np.zeros(3), radius=0.02)
    state, _ = doll_engine.step(settled, StepInput(pointer=far))
    assert names(doll, ~state.body_asleep) == {"hips"}


def test_a_moving_neighbour_wakes_a_sleeper_but_a_resting_one_does_not():
    # Two free balls (r = 5 cm), no gravity, each its own island: the first asleep, the
    # second 10 cm away.  Still, it never wakes the sleeper; moving towards it at 0.5 m/s
    # (2.5 mm a step) it wakes it at the first step that starts within contact reach
    # (the contact margin), before they touch.
    ball = ShapeSpec("sphere", radius=0.05)
    shapes = [(ball, np.array([0.0, y, 0.0]), np.array([0.0, y + 0.01, 0.0])) for y in (0.0, 0.2)]
    model = free_bodies(shapes, 0.005, gravity=False, ground=False)
    engine = Engine(model)
    start = replace(initial_state(model), body_asleep=np.array([True, False]))
    state = start
    for _ in range(50):
        state, _ = engine.step(state)
    assert state.body_asleep[0]
    state = replace(start, body_vel=np.array([[0.0, 0.0, 0.0], [0.0, -0.5, 0.0]]))
    gaps = []
    while state.body_asleep[0] and len(gaps) < 100:
        gaps.append(state.body_pos[1, 1] - state.body_pos[0, 1] - 0.1)
        state, _ = engine.step(state)
    margin = model.options.contact_margin
    assert margin - 0.0025 < gaps[-1] <= margin < gaps[-2]


def test_sleeping_matches_the_numpy_step(doll):
    # Both steps call the same sleep and wake functions: lockstep through falling asleep
    # (the upper body first, ~0.6 s) and waking by a grip.
    doll_engine = Engine(doll)
    state = initial_state(doll)
    for _ in range(150):
        state, _ = doll_engine.step(state)
    inputs = [None] * 60 + grip_inputs(doll, 0.2, 40)
    reports = lockstep(doll, state, inputs)
    assert min(r.rows for r in reports) < max(r.rows for r in reports)


def test_sleeping_changes_the_motion_by_less_than_its_thresholds_allow(doll, settled):
    # The settled doll's left forearm lifted for 1 s: the legs sleep through it.  Awake,
    # the legs would only have moved by what their residual speeds (below 5e-4 m/s)
    # carry them: the two runs differ by 6.8e-6 m and 1.1e-5 rad (measured).
    doll_engine = Engine(doll)
    off = doll.with_options(sleep=False)
    off_engine = Engine(off)
    inputs = grip_inputs(doll, 1.0, 200)
    a = b = replace(
        settled, body_asleep=np.zeros(doll.nbody, bool), body_still=np.zeros(doll.nbody)
    )
    worst_pos = worst_rot = 0.0
    for inp in inputs:
        a, _ = doll_engine.step(a, inp)
        b, _ = off_engine.step(b, inp)
        worst_pos = max(worst_pos, float(np.abs(a.body_pos - b.body_pos).max()))
        rot = quat.log(quat.mul(quat.conj(a.body_quat), b.body_quat))
        worst_rot = max(worst_rot, float(np.linalg.norm(rot, axis=1).max()))
    assert names(doll, a.body_asleep) == set(LEGS)
    assert worst_pos < 3.4e-5 and worst_rot < 5.5e-5, (worst_pos, worst_rot)
