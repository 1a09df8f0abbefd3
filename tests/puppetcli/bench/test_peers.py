"""MuJoCo as a peer: the translated rig against our model and closed forms, the two
engines against each other, and the error measures against first-order theory."""

from __future__ import annotations

import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest

from puppetcli.bench import peers
from puppetcli.bench import scenes as precision_scenes
from puppetcli.bench.peers import PeerGrip, build_peer, drive, peer_tails, run
from puppetcli.rig.load import load_rig
from puppetcli.spidar.pointer import Motion, pointer_over_step
from solver import quat
from solver.model import build_model
from solver.observe import bone_tails
from solver.pipeline import step
from solver.spec import BoneSpec, GroundSpec, RheologySpec, RigSpec, ShapeSpec
from solver.state import initial_state

try:
    import mujoco
except ImportError:  # the peers marker skips (or, in CI, fails) the tests that need it
    mujoco = None

G = 9.81


def _free_body(shape: ShapeSpec, head, tail, gravity=(0.0, -G, 0.0), ground=None):
    """One free 1 kg bone (its centre of mass at the shape centre)."""
    bone = BoneSpec(
        "body", None, np.array(head, float), np.array(tail, float), shape, 1.0,
        collide=ground is not None,
    )  # fmt: skip
    spec = RigSpec("body", (bone,), "free", np.array(gravity, float), ground)
    return build_model(spec)


def test_importing_peers_does_not_import_mujoco():
    modules = "puppetcli.bench.peers, puppetcli.commands.bench"
    code = f"import sys, {modules}; print('mujoco' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
    assert peers.mujoco_version() == mujoco.__version__


@pytest.mark.peers
def test_doll_masses_inertias_and_anchors_are_ours():
    model = peers.doll_model()
    peer = build_peer(model, 0.001)
    m, d = peer.mj_model, peer.mj_data
    mujoco.mj_forward(m, d)
    ids = peer.body_ids
    assert m.body_mass.sum() == pytest.approx(model.body_mass.sum(), rel=1e-12)
    assert np.allclose(m.body_mass[ids], model.body_mass, rtol=1e-12)
    ours = np.sort(np.linalg.eigvalsh(model.body_inertia), axis=1)
    assert np.allclose(np.sort(m.body_inertia[ids], axis=1), ours, rtol=1e-9, atol=1e-15)
    # MuJoCo's own kinematics: centres of mass and joint anchors where our rest pose has them.
    assert np.allclose(d.xipos[ids], model.body_pos0, atol=1e-12)
    joint = [m.joint(name).id for name in model.joint_names]
    assert np.allclose(d.xanchor[joint], model.bone_head0[model.joint_bone], atol=1e-12)
    assert m.nv == 3 * model.njoint  # hips welded to the stand, every other bone a ball


@pytest.mark.peers
def test_doll_contacts_only_our_pairs():
    """At rest the doll touches nothing (feet 1 cm up) once the pairs overlapping at rest
    and parent–child pairs are dropped; MuJoCo's default filter would find overlaps."""
    model = peers.doll_model()
    peer = build_peer(model, 0.001)
    mujoco.mj_forward(peer.mj_model, peer.mj_data)
    assert peer.mj_data.ncon == 0
    xml = peer.mjcf.xml.replace('contype="0" conaffinity="0"', "")
    default = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(default)
    mujoco.mj_forward(default, data)
    assert data.ncon > 0


@pytest.mark.parametrize(
    ("shape", "height"),
    [
        (ShapeSpec("capsule", radius=0.05), 0.05),  # lies on its side: axis along x
        (ShapeSpec("box", half_extents=(0.1, 0.15, 0.05)), 0.1),  # bone y → world x
    ],
)
@pytest.mark.peers
def test_body_comes_to_rest_on_the_y_up_ground(shape, height):
    model = _free_body(shape, (0.0, 0.2, 0.0), (0.3, 0.2, 0.0), ground=GroundSpec(0.0, 0.8))
    peer = build_peer(model, 0.002)
    run(peer, 750)
    assert peer.mj_data.xpos[peer.body_ids[0], 1] == pytest.approx(height, abs=1e-3)
    assert np.linalg.norm(peer.mj_data.qvel) < 1e-3


def _grip_peer(model, integrator, motion, steps, h=0.001):
    c = model.body_pos0[0]
    grip = PeerGrip(0, np.zeros(3), c, peers.GRIP_K, peers.GRIP_D, 300.0)
    return drive(build_peer(model, h, integrator, grip), motion, grip, steps), grip


@pytest.mark.peers
@pytest.mark.parametrize("integrator", ["Euler", "implicitfast"])
def test_grip_static_pull_is_k_times_e(integrator):
    """A 1 kg body hanging from a still pointer sags by m·g/K, and the coupling's force
    is K·e = m·g straight up."""
    model = _free_body(ShapeSpec("sphere", radius=0.05), (0, 1, 0), (0, 1.1, 0))
    c = model.body_pos0[0]
    still = Motion(0.0, 1.0, c, quat.IDENTITY, np.zeros(3), np.zeros(3))
    peer, _ = _grip_peer(model, integrator, still, 1000)
    run(peer, 1000)
    sag = c - peer.mj_data.xpos[peer.body_ids[0]]
    assert sag == pytest.approx([0.0, G / peers.GRIP_K, 0.0], rel=0.02, abs=1e-9)
    assert peer.mj_data.actuator_force == pytest.approx([0.0, G, 0.0], rel=0.02, abs=1e-6)


@pytest.mark.peers
def test_grip_damper_acts_on_the_relative_velocity():
    """Dragged without gravity at the middle of a min-jerk move (zero acceleration), a
    Voigt coupling −K·e − D·(v − u) needs no stretch; one damping absolute velocity
    (a mocap body's view) would lag by D·u/K."""
    model = _free_body(ShapeSpec("sphere", radius=0.05), (0, 1, 0), (0, 1.1, 0), (0, 0, 0))
    c = model.body_pos0[0]
    move = Motion(0.0, 2.0, c, quat.IDENTITY, np.array([0.4, 0.0, 0.0]), np.zeros(3))
    u = 1.875 * 0.4 / 2.0  # s'(1/2) · distance / duration
    peer, _ = _grip_peer(model, "Euler", move, 1000)
    run(peer, 1000)
    lag = peer.mj_data.xpos[peer.body_ids[0]] - move.pose(1.0)[0]
    assert np.linalg.norm(lag) < 0.01 * peers.GRIP_D * u / peers.GRIP_K
    absolute = replace(peer, ctrl=np.zeros_like(peer.ctrl))
    peers.reset(absolute)
    run(absolute, 1000)
    lag = absolute.mj_data.xpos[peer.body_ids[0]] - move.pose(1.0)[0]
    assert -lag[0] == pytest.approx(peers.GRIP_D * u / peers.GRIP_K, rel=0.02)


@pytest.mark.peers
def test_pointer_path_is_the_runners_pointer():
    motion = Motion(0.1, 0.5, np.array([0.7, 1.36, 0.0]), quat.IDENTITY, peers.LIFT, np.zeros(3))
    h = 0.01
    pos, vel = peers.pointer_path(motion, h, 70)
    expected = [pointer_over_step(motion, k * h, h, 0.0) for k in range(70)]
    assert np.allclose(pos, [p.pos for p in expected], atol=1e-14)
    assert np.allclose(vel, [p.vel for p in expected], atol=1e-11)


# Cross-engine: both engines are first order, so at step h each is off its own limit by
# ≈ C·h and their difference is ≈ (C_ours − C_mj)·h: it halves with h when both converge
# to the same motion, and Richardson's 2·x(h/2) − x(h) of the two then agrees to O(h²).
# A mistranslated rig converges elsewhere: its difference stalls at the modelling gap.
CROSS_T, CROSS_TIMES = 0.3, np.arange(1, 7) * 0.05


def _chain(rheology):
    spec = load_rig(precision_scenes.RIGS / "chain.yaml")
    bones = tuple(replace(b, rheology=rheology, collide=False) for b in spec.bones)
    return build_model(replace(spec, ground=None, bones=bones))


def _our_tips(model, h):
    m = model.with_options(h=h, method="direct")
    state, marks, tips = initial_state(m), {round(t / h) for t in CROSS_TIMES}, []
    for k in range(1, round(CROSS_T / h) + 1):
        state, _ = step(m, state)
        if k in marks:
            tips.append(bone_tails(m, state)[-1])
    return np.array(tips)


def _peer_tips(model, h):
    marks = [round(t / h) for t in CROSS_TIMES]
    _, _, tips = run(build_peer(model, h), marks[-1], lambda p: peer_tails(p)[-1].copy(), marks)
    return np.array(tips)


def _gap(a, b):
    return float(np.max(np.linalg.norm(a - b, axis=1)))


@pytest.mark.parametrize(
    "rheology",
    [None, RheologySpec(np.full(3, 5.0), np.full(3, 0.2), np.full(3, np.inf))],
    ids=["bare", "voigt"],
)
@pytest.mark.peers
def test_chain_falls_the_same_in_both_engines(rheology):
    """The 10-link chain released horizontally: bare (anchors only), and with Voigt
    joints (K_f = 5, D_f = 0.2, no D_d) whose springs change the tip by ~0.1 m."""
    model = _chain(rheology)
    ours = {h: _our_tips(model, h) for h in (0.002, 0.001)}
    theirs = {h: _peer_tips(model, h) for h in (0.002, 0.001)}
    coarse, fine = _gap(ours[0.002], theirs[0.002]), _gap(ours[0.001], theirs[0.001])
    assert 0.4 < fine / coarse < 0.6
    richardson = _gap(2 * ours[0.001] - ours[0.002], 2 * theirs[0.001] - theirs[0.002])
    assert richardson < 0.02 * fine  # measured: 0.3 % (bare), 0.4 % (Voigt)
    if rheology is not None:
        assert _gap(theirs[0.001], _peer_tips(_chain(None), 0.001)) > 100 * richardson


def _first_order_ratio(h, ref_h):
    """e(2h)/e(h) for errors measured against a first-order reference at ref_h."""
    return (2 * h - ref_h) / (h - ref_h)


@pytest.mark.peers
def test_chain_error_is_first_order_against_its_reference():
    ref_h = 2.5e-4
    coarse, fine = (peers.chain_error(h, reference_h=ref_h) for h in (0.002, 0.001))
    ratio = _first_order_ratio(0.001, ref_h)
    assert coarse["error_1s"] / fine["error_1s"] == pytest.approx(ratio, rel=0.1)
    # the reference's own error (its distance to 2·ref_h) is the same C·ref_h, worst at 3 s
    expected = fine["error_3s"] * ref_h / (0.001 - ref_h)
    assert fine["ref_error"] == pytest.approx(expected, rel=0.15)
    assert not fine["diverged"] and fine["steps"] == 3000


@pytest.mark.peers
def test_doll_error_is_first_order_against_its_reference():
    ref_h = 2.5e-4
    coarse, fine = (peers.doll_error(h, reference_h=ref_h) for h in (0.002, 0.001))
    assert coarse["error"] / fine["error"] == pytest.approx(_first_order_ratio(0.001, ref_h), 0.1)
    expected = fine["error"] * ref_h / (0.001 - ref_h)
    assert fine["ref_error"] == pytest.approx(expected, rel=0.15)


@pytest.mark.peers
def test_stability_reports_joint_anchors_held_and_the_lift():
    out = peers.stability(0.02)
    assert out["finite"] and not out["diverged"] and out["warnings"] == {}
    # the parent's anchor, from the parent's frame, meets the child's: the joints are right
    assert out["max_anchor_gap"] < 1e-12
    assert 0.0 < out["grip_rise"] < peers.LIFT[1]  # Voigt joints resist part of the lift


@pytest.mark.peers
def test_doll_timer_runs_the_bench_step_count():
    out = peers.doll_timer(0.01, 0.05)()
    assert out["steps"] == 5 and out["steps_per_s"] > 0 and not out["diverged"]
