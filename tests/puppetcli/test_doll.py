"""Scenarios on rigs/doll.yaml: it holds poses with yield and creeps at τ/D_d without."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from puppetcli.rig.load import load_rig, rig_from_text
from solver import quat
from solver.model import build_model
from solver.observe import joint_rotations
from solver.pipeline import step
from solver.state import initial_state

DOLL = Path(__file__).resolve().parents[2] / "rigs" / "doll.yaml"
ARM = ("upper_arm_l", "forearm_l", "hand_l")


def simulate(model, seconds: float, sample_at: list[float]):
    """Joint rotations (nj,3) at the requested times."""
    state = initial_state(model)
    out = {}
    for k in range(1, round(seconds / model.options.h) + 1):
        state, _ = step(model, state)
        for t in sample_at:
            if abs(k * model.options.h - t) < 0.5 * model.options.h:
                out[t] = (joint_rotations(model, state), state)
    return out


def test_doll_with_yield_holds_its_raised_arms_under_gravity():
    model = build_model(load_rig(DOLL))
    samples = simulate(model, 10.5, [0.5, 10.5])
    before, after = samples[0.5][0], samples[10.5][0]
    drift = np.degrees(np.linalg.norm(after - before, axis=1))
    worst = {model.joint_names[j]: round(float(drift[j]), 3) for j in np.argsort(drift)[-3:]}
    assert drift.max() < 0.5, worst


def arm_gravity_torque(model, state) -> np.ndarray:
    """Gravity torque of the left arm about the shoulder anchor, in the chest frame (N·m)."""
    j = model.joint_names.index("upper_arm_l")
    chest = model.joint_parent[j]
    shoulder = state.body_pos[chest] + quat.rotate(
        state.body_quat[chest], model.joint_anchor_parent[j]
    )
    torque = np.zeros(3)
    for name in ARM:
        b = model.body_names.index(name)
        torque += np.cross(state.body_pos[b] - shoulder, model.body_mass[b] * model.options.gravity)
    return quat.rotate(quat.conj(state.body_quat[chest]), torque)


def test_doll_without_yield_creeps_at_the_rate_torque_over_dd():
    # No yield anywhere, and no side table (the sinking hand would come to rest on it).
    text = re.sub(r"yield: [0-9.]+, ", "", DOLL.read_text()).split("\nprops:")[0]
    model = build_model(rig_from_text(text, "doll-without-yield.yaml"))
    assert not np.isfinite(model.joint_yield).any()
    t0, t1 = 1.0, 1.2
    samples = simulate(model, t1, [t0, 0.5 * (t0 + t1), t1])
    j = model.joint_names.index("upper_arm_l")
    rate = (samples[t1][0][j] - samples[t0][0][j]) / (t1 - t0)
    torque = arm_gravity_torque(model, samples[0.5 * (t0 + t1)][1])
    expected = torque / model.joint_dd[j]
    assert abs(expected[2]) > 0.1  # the arm sags measurably (rad/s about the chest's z)
    assert rate[2] == pytest.approx(expected[2], rel=0.05)  # measured 2.0 % (elastic part)
