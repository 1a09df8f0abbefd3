"""Posing by hand on rigs/doll.yaml: grip, pull, twist, release, touch, feel."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from puppetcli.rig.load import rig_from_text
from puppetcli.run.runner import Runner, script_model
from puppetcli.script.load import script_from_text
from solver import quat
from solver.model import build_model
from solver.observe import bone_heads, bone_tails, joint_rotations

DOLL = Path(__file__).resolve().parents[3] / "rigs" / "doll.yaml"
PULL = """
pointer: {start: [0.70, 1.36, 0.0]}
actions:
  - grip: {bone: forearm_l, point: [0.24, 0, 0], position_only: true}
  - move: {by: [0.0, 0.0, 0.2], duration: 1.0}
  - key: release
  - release:
  - wait: 2.0
  - key: after
"""


def prepare(script: str, rig_text: str | None = None) -> Runner:
    spec = rig_from_text(rig_text or DOLL.read_text(), "doll.yaml")
    plan = script_from_text(script, "test.yaml", spec)
    return Runner(script_model(build_model(spec), plan), plan)


def run(script: str, rig_text: str | None = None, log=None):
    runner = prepare(script, rig_text)
    runner.on_step = log
    return runner.model, runner, runner.run()


def rotation_of(key, bone: str) -> np.ndarray:
    return quat.log(key.bones[bone].local)


@pytest.fixture(scope="module")
def pulled():
    """The elbow pulled 20 cm by the forearm's end, released, left 2 s: per-step log."""
    log = []
    model, _, result = run(PULL, log=lambda s: log.append(s))
    return model, result, log


def test_plastic_posing_keeps_most_of_the_new_angle(pulled):
    _, result, _ = pulled
    released, after = (rotation_of(k, "forearm_l") for k in result.keys)
    assert np.degrees(np.linalg.norm(released)) > 15.0  # measured 23.2°
    assert np.linalg.norm(after) > 0.85 * np.linalg.norm(released)  # measured 92.7 %


def test_spring_back_is_the_elastic_part_at_release(pulled):
    # After release the joint re-anchors at "pose minus elastic part" and springs
    # back by q_sf(release) − q_sf(end) (q_sf(end) = its static gravity sag).  On the
    # rotation group the two agree up to the composition of rotations, whose
    # second-order (BCH) term ½|θ|·|Δq| bounds the difference in rotation vectors;
    # any flow of the damper while the yield filter catches up adds |λ|h/D_d per step.
    model, _, log = pulled
    j = model.joint_names.index("forearm_l")
    k = next(i for i, s in enumerate(log) if abs(s.time - 1.0) < 1e-9)
    at_release, end = log[k], log[-1]
    spring_back = joint_rotations(model, at_release)[j] - joint_rotations(model, end)[j]
    elastic = at_release.joint_q_sf[j] - end.joint_q_sf[j]
    flow = sum(np.linalg.norm(s.joint_torque[j]) for s in log[k + 1 :] if s.joint_yielded[j])
    bound = 0.5 * np.linalg.norm(joint_rotations(model, at_release)[j]) * np.linalg.norm(elastic)
    bound += flow * model.options.h / model.joint_dd[j, 0]
    assert np.degrees(np.linalg.norm(elastic)) > 1.0  # a visible spring-back
    assert np.linalg.norm(spring_back - elastic) <= bound  # measured 0.60 of it


def test_elastic_part_at_rest_balances_the_joint_torque(pulled):
    # At rest a Voigt element carries the torque with its spring alone: λ = −K_f q_sf.
    model, _, log = pulled
    j = model.joint_names.index("forearm_l")
    end = log[-1]
    # measured 1.1e-5 rad (of 0.02 rad)
    assert end.joint_q_sf[j] == pytest.approx(-end.joint_torque[j] / model.joint_kf[j], abs=6e-5)


def test_pure_voigt_joint_returns_to_rest_but_for_its_gravity_sag():
    text = DOLL.read_text().replace("dd: 8.0, yield: 4.5", "plastic: false")
    model, runner, result = run(PULL, text)
    released, after = (rotation_of(k, "forearm_l") for k in result.keys)
    state = runner.state
    j = model.joint_names.index("forearm_l")
    elbow = bone_heads(model, state)[model.bone_names.index("forearm_l")]
    torque = sum(
        np.cross(state.body_pos[b] - elbow, model.body_mass[b] * model.options.gravity)
        for b in (model.bone_names.index("forearm_l"), model.bone_names.index("hand_l"))
    )
    sag = np.linalg.norm(torque) / model.joint_kf[j, 0]  # static Voigt deflection τ/K_f
    assert np.linalg.norm(after) == pytest.approx(sag, rel=1e-3)  # measured 2.0e-4
    assert np.linalg.norm(after) < 0.4 * np.linalg.norm(released)  # measured 0.28


def test_twisting_the_gripped_hand_twists_the_wrist():
    model, runner, _ = run(
        "pointer: {start: [0.76, 1.36, 0.0]}\n"
        "actions:\n  - grip: hand_l\n  - twist: {angle: 45, duration: 1.0}\n  - wait: 0.5\n"
    )
    rot = np.degrees(joint_rotations(model, runner.state)[model.joint_names.index("hand_l")])
    # About the forearm's axis (+x at rest).  The wrist yields and flows until its torque
    # falls to its yield torque τ_y; at rest that torque holds, elastically, the grip's
    # rotational spring (the script's default, 50 N·m/rad) and every joint between the
    # stand and the wrist, in series: the wrist turns 45° less τ_y·(1/50 + Σ 1/K_f).
    wrist = model.joint_names.index("hand_l")
    chain = [model.joint_names.index(n) for n in ("spine", "chest", "upper_arm_l", "forearm_l")]
    compliance = 1.0 / 50.0 + sum(1.0 / model.joint_kf[j, 0] for j in chain)
    expected = 45.0 - np.degrees(model.joint_yield[wrist] * compliance)  # 42.228°
    assert rot[0] == pytest.approx(expected, abs=0.06)  # measured 42.240°
    assert np.hypot(rot[1], rot[2]) < 3.0  # measured 1.06°


def test_posing_the_left_arm_leaves_the_right_leg_alone(pulled):
    # Against the same doll left alone for the same time (its feet sag a little
    # under their own weight either way).
    _model, result, _ = pulled
    _, _, alone = run("actions:\n  - wait: 1.0\n  - key: release\n  - wait: 2.0\n  - key: after\n")
    for posed, still in zip(result.keys, alone.keys, strict=True):
        for bone in ("thigh_r", "shin_r", "foot_r"):
            moved = quat.log(quat.mul(posed.bones[bone].local, quat.conj(still.bones[bone].local)))
            assert np.degrees(np.linalg.norm(moved)) < 1e-9  # measured 0: the same floats


def test_hand_pushed_onto_the_table_stops_on_it():
    runner = prepare(
        "pointer: {start: [0.76, 1.36, 0.0]}\nactions:\n"
        "  - grip: {bone: hand_l, position_only: true}\n"
        "  - move: {by: [0.0, -0.25, 0.0], duration: 1.0}\n  - wait: 0.5\n"
    )
    model, hand = runner.model, runner.model.bone_names.index("hand_l")
    lowest = []  # the hand capsule's lowest point (radius 0.03) after each step
    runner.on_step = lambda s: lowest.append(
        min(bone_heads(model, s)[hand][1], bone_tails(model, s)[hand][1]) - 0.03
    )
    runner.run()
    table_top = 1.2
    assert min(lowest) > table_top - 6e-4  # penetration measured 0.13 mm (slop 0.5 mm)
    assert min(lowest) < table_top + 0.005  # and it did reach the table
