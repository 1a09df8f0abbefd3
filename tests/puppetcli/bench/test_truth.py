"""The like-for-like study's truth (puppetcli.bench.truth) and its bookkeeping
(puppetcli.bench.likeforlike) against values they do not compute.

- Energy: with no damping the joint-coordinate equations conserve kinetic + gravity +
  spring energy (½K|log q|² is the potential of the torque −K log q); a 3-link chain
  thrown with random joint velocities keeps it to 5e-13 J over 0.3 s.
- A damped oscillator: one body turning about its centre (the joint) with an isotropic
  inertia follows θ(t) = e^{−αt}(θ₀ cos ω_d t + (αθ₀/ω_d) sin ω_d t).
- A posed start: the bodies the truth's kinematics places keep every joint's two anchors
  together (solver.observe.joint_gaps, the solver's own geometry).
- The equal-time reading: runs whose error is C·h² at cost k/h give, at level E, exactly
  k/√(E/C) (log-log interpolation is exact on power laws).
- The floor: a rod hinged at its head and resting its tail on it presses with half its
  weight (moments about the joint); a frictionless floor does no work, so a chain
  sliding on it keeps its energy, and its point stays on the plane (read off the forward
  kinematics, not the constraint's own row); the floor scene's contact never pulls.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from puppetcli.bench import likeforlike
from puppetcli.bench import truth as ode
from solver.observe import joint_gaps


def test_energy_is_conserved_without_damping():
    model = likeforlike.voigt_model("chain.yaml", 3, 0.5, 0.0)
    tree = ode.make_tree(model)
    rng = np.random.default_rng(7)
    q = Rotation.from_rotvec(rng.normal(size=(3, 3)) * 0.5).as_quat(scalar_first=True)
    y0 = np.concatenate((q.ravel(), rng.normal(size=9) * 2.0))
    ys = ode.integrate(tree, y0, np.linspace(0.05, 0.3, 6))
    e0 = ode.energy(tree, y0)
    drift = max(abs(ode.energy(tree, y) - e0) for y in ys)
    # measured: 9.8e-14 J of 8.8 J (the energy moves between its three kinds)
    assert drift < 5e-13


def test_a_damped_body_follows_the_closed_form():
    k, d, inertia, theta0 = 1.0, 0.3, 0.1, 0.5
    model = likeforlike.voigt_model("one_bone.yaml", None, k, d)
    assert np.allclose(model.body_inertia[0], inertia * np.eye(3))  # the rig's, isotropic
    model = model.with_options(gravity=np.zeros(3))
    tree = ode.make_tree(model)
    times = np.linspace(0.1, 2.0, 20)
    y0 = np.concatenate((Rotation.from_rotvec([0.0, 0.0, theta0]).as_quat(scalar_first=True),
                         np.zeros(3)))  # fmt: skip
    ys = ode.integrate(tree, y0, times)
    got = Rotation.from_quat(ys[:, :4], scalar_first=True).as_rotvec()[:, 2]
    alpha = d / (2.0 * inertia)
    wd = math.sqrt(k / inertia - alpha**2)
    want = np.exp(-alpha * times) * (
        theta0 * np.cos(wd * times) + alpha * theta0 / wd * np.sin(wd * times)
    )
    # measured: 1.9e-12 rad (DOP853 at rtol 1e-12)
    assert np.abs(got - want).max() < 1e-11


def test_a_posed_start_keeps_the_joints_together():
    model = likeforlike.voigt_model("doll.yaml")
    state = likeforlike.posed(model, np.random.default_rng(1).normal(size=(model.njoint, 3)))
    # measured: 2.2e-16 m; the bodies moved by up to 1.2 m from their rest
    assert joint_gaps(model, state.body_pos, state.body_quat).max() < 1e-15
    assert np.abs(state.body_pos - model.body_pos0).max() > 0.3


def _runs(c: float, k: float, engine: str) -> list:
    return [likeforlike.Run("s", engine, h, c * h * h, c * h * h, k / h)
            for h in (0.001, 0.002, 0.004, 0.008)]  # fmt: skip


def test_equal_time_interpolates_power_laws_exactly():
    ours, peer = _runs(2.0, 1e-6, "bdf2"), _runs(0.5, 4e-6, "MuJoCo RK4")
    level = 1.3e-5  # between the steps 2 and 4 ms
    got = likeforlike.cost_at(ours, level)
    assert math.isclose(got, 1e-6 / math.sqrt(level / 2.0), rel_tol=1e-12)
    rows = likeforlike.equal_time(ours + peer, levels=(level,))
    want = (1e-6 / math.sqrt(level / 2.0)) / (4e-6 / math.sqrt(level / 0.5))
    assert math.isclose(rows[0].ratio, want, rel_tol=1e-12)
    # a level no run reaches has no cost; one every run beats costs the cheapest run
    assert likeforlike.cost_at(ours, 1e-9) == math.inf
    assert likeforlike.cost_at(ours, 1.0) == min(r.cost for r in ours)
    assert likeforlike.cost_at([replace(r, rms=math.inf) for r in ours], 1.0) == math.inf


def test_a_rod_resting_on_the_floor_presses_with_half_its_weight():
    # one link hinged at its head, at rest with its tail on the floor: moments about the
    # joint give N·L = m·g·L/2 (the spring is at rest, nothing moves)
    model = likeforlike.voigt_model("chain.yaml", 1, 0.5, 0.0)
    tree = ode.make_tree(model)
    b = int(tree.child[0])
    point = model.bone_tail0[b] - model.body_pos0[b]
    floor = ode.Floor(b, point, float(model.bone_tail0[b][1]))
    y0 = ode.joint_state(tree, model.body_quat0, np.zeros((model.nbody, 3)))
    got = ode.floor_force(tree, 0.0, y0, floor)
    want = model.body_mass[b] * 9.81 / 2.0
    # measured: 3.3e-16 N apart
    assert math.isclose(got, want, rel_tol=1e-14)
    # and nothing accelerates: the floor holds the rod where it is
    assert np.abs(ode.derivative(tree, 0.0, y0, None, floor)).max() < 1e-12


def test_the_floor_does_no_work_and_keeps_the_point_on_it():
    # chain-floor without damping: a frictionless floor's force is normal to the point's
    # motion, so kinetic + gravity + spring energy is conserved, and p_y stays put
    sc = likeforlike.scene("chain-floor")
    tree = ode.make_tree(likeforlike.voigt_model("chain.yaml", 4, likeforlike.CHAIN_K, 0.0))
    rng = np.random.default_rng(3)
    y0 = ode.joint_state(tree, sc.start.body_quat, sc.start.body_omega)
    k = 4 * len(tree.joint)
    y0[k:] = _on_the_plane(tree, y0, sc.floor, rng.normal(size=len(y0) - k) * 0.5)
    times = np.linspace(0.05, 0.5, 10)
    ys = ode.integrate(tree, y0, times, None, sc.floor)
    e0 = ode.energy(tree, y0)
    drift = max(abs(ode.energy(tree, y) - e0) for y in ys)
    # measured: 5.3e-15 J of 10.9 J; the point's height moved 4.4e-16 m
    assert drift < 2e-14
    heights = [_tail(tree, y, sc.floor)[0][1] for y in ys]
    assert np.abs(np.array(heights) - sc.floor.height).max() < 2e-15
    pushes = [ode.floor_force(tree, t, y, sc.floor) for t, y in zip(times, ys, strict=True)]
    assert min(pushes) > 0.0  # measured: 0.11 N at least (it never pulls)


def _tail(tree, y: np.ndarray, floor) -> tuple[np.ndarray, np.ndarray]:
    """The floor's point: position and velocity by the forward kinematics."""
    n = len(tree.joint)
    kin = ode.kinematics(tree, y[: 4 * n].reshape(n, 4), y[4 * n :].reshape(n, 3))
    lever = kin.rot[floor.body] @ floor.point
    return kin.pos[floor.body] + lever, kin.vel[floor.body] + np.cross(kin.omega[floor.body], lever)


def _on_the_plane(tree, y: np.ndarray, floor, u: np.ndarray) -> np.ndarray:
    """u less its part that moves the point off the plane (ṗ_y is linear in u: its row
    read off the kinematics one unit velocity at a time)."""
    k = 4 * len(tree.joint)
    row = np.array([_tail(tree, np.concatenate((y[:k], e)), floor)[1][1] for e in np.eye(len(u))])
    return u - row * (row @ u) / (row @ row)


def test_the_floor_scene_presses_on_its_floor_all_along():
    # chain-floor's premise: the contact never lets go over the study's 1 s and the large
    # steps' 2 s, so the truth's bilateral constraint is the contact both engines model
    sc = likeforlike.scene("chain-floor")
    tree = ode.make_tree(sc.model)
    times = np.linspace(0.02, 2.0, 100)
    y0 = ode.joint_state(tree, sc.start.body_quat, sc.start.body_omega)
    ys = ode.integrate(tree, y0, times, None, sc.floor, rtol=1e-10, atol=1e-10)
    pushes = [ode.floor_force(tree, t, y, sc.floor) for t, y in zip(times, ys, strict=True)]
    # measured: 0.76 to 3.47 N (the chain's weight is 7.8 N)
    assert min(pushes) > 0.5
    assert _tail(tree, y0, sc.floor)[0][1] == pytest.approx(sc.floor.height, abs=1e-15)


def test_the_equal_time_table_says_who_alone_reaches_a_level():
    ours, peer = _runs(2.0, 1e-6, "bdf2"), _runs(0.5, 4e-6, "MuJoCo RK4")
    rows = likeforlike.equal_time(ours + peer, levels=(1e-6, 1.3e-5, 1e-9))
    # 1e-6 m: only the peer's errors (down to 3.2e-7) reach it; 1e-9: nobody's
    assert rows[0].ratio == math.inf and math.isnan(rows[2].ratio)
    mujoco_only = likeforlike.equal_time(peer + [replace(r, rms=math.inf) for r in ours],
                                         levels=(1.3e-5,))  # fmt: skip
    bdf2_only = likeforlike.equal_time(ours + [replace(r, rms=math.inf) for r in peer],
                                       levels=(1.3e-5,))  # fmt: skip
    text = likeforlike.format_equal_time(rows + mujoco_only + bdf2_only).splitlines()
    assert text[2].endswith("only MuJoCo reaches it") and text[4].endswith("   -")
    assert text[3].endswith(f"{rows[1].ratio:.2f}")
    assert text[5].endswith("only MuJoCo reaches it") and text[6].endswith("only bdf2 reaches it")
