"""The joint-space step (solver.advance.joint_space, its kernel and
solver.compiled.joint_sim.JointSim) against values it does not compute.

- A link twisting about its own axis (a principal axis through the pivot and its centre
  of mass, no gravity: one degree of freedom, linear) follows BDF2's exact scalar
  recursion, restart parts included.
- The compiled step (the articulated-body recursion) equals the dense numpy specification
  (every matrix built whole and solved by numpy) on the pulled doll and a bent chain.
- A chain released from a 3-D bend converges to the truth (puppetcli.bench.truth: Kane's
  equations in reduced coordinates, DOP853) at second order.
- At 250 ms steps the hanging chain stays near the truth (its steps taken in parts).
- Inputs it cannot take hand the run to the maximal-coordinate stepper, whose step from
  the handed state is the oracle; a broken state stops with the monitor's message.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_bdf2 import released_chain_tips

from puppetcli.bench import likeforlike, scenes
from solver import quat
from solver.advance import joint_space
from solver.advance.joint_space_kernel import CLOCK_HPREV
from solver.compiled.joint_sim import JointSim
from solver.compiled.sim import Sim
from solver.engine import Engine
from solver.errors import SimulationError
from solver.rows.pin import Pin
from solver.state import StepInput

K, D = likeforlike.CHAIN_K, likeforlike.CHAIN_D


def _twist_model(h: float):
    model = likeforlike.voigt_model("chain.yaml", 1, K, D)
    return model.with_options(h=h, integrator="bdf2", gravity=np.zeros(3))


def twist_recursion(h: float, steps: int, theta0: float, inertia: float,
                    tau: float = 0.0) -> np.ndarray:  # fmt: skip
    """The twist angle after every step: I(ω − ω̂) = γ(τ − Kθ − Dω), θ = θ̂ + γω, with
    x̂ = x + c(x − x_prev), c = r²/(1 + 2r), γ = k(1 + r)/(1 + 2r) for a part of length k at
    r = k/k_prev; the first step in parts h/4 (backward Euler), h/4, h/2."""
    theta, omega, theta_prev, omega_prev, k_prev, out = theta0, 0.0, theta0, 0.0, 0.0, []
    for n in range(steps):
        for k in (h / 4, h / 4, h / 2) if n == 0 else (h,):
            r = k / k_prev if k_prev > 0.0 else 0.0
            c, gamma = r * r / (1.0 + 2.0 * r), k * (1.0 + r) / (1.0 + 2.0 * r)
            th_hat = theta + c * (theta - theta_prev)
            om_hat = omega + c * (omega - omega_prev)
            w = (inertia * om_hat + gamma * (tau - K * th_hat)) / (
                inertia + gamma * D + gamma**2 * K
            )
            theta_prev, omega_prev, k_prev = theta, omega, k
            theta, omega = th_hat + gamma * w, w
        out.append(theta)
    return np.array(out)


@pytest.mark.parametrize(("theta0", "tau"), [(0.3, 0.0), (0.0, 0.01)])
def test_a_twisting_link_follows_the_exact_bdf2_recursion(theta0, tau):
    # released from a twist, or twisted from rest by a torque about its axis (a load)
    h, steps = 0.002, 100
    model = _twist_model(h)
    axis = model.bone_tail0[1] - model.bone_head0[1]
    axis /= np.linalg.norm(axis)
    start = likeforlike.posed(model, np.array([theta0 * axis]))
    sim = Engine(model).stepper(start)
    assert isinstance(sim, JointSim)
    torque = np.zeros((model.nbody, 3))
    torque[1] = tau * axis
    loaded = StepInput(body_torque=torque) if tau else None
    angles = []
    for _ in range(steps):
        sim.advance(loaded)
        angles.append(quat.log(sim.view().body_quat[1]) @ axis)
    assert sim.report.solver == "joint-space"
    inertia = axis @ model.body_inertia[1] @ axis
    expected = twist_recursion(h, steps, theta0, inertia, tau)
    # measured: 1.9e-16 rad over 100 steps released, 2.1e-17 under the torque (the step's
    # spatial quantities are about the root's anchor; about the world origin, 1.5 m away,
    # the link's 0.45 kg·m² swamped the 2.2e-5 about its axis: 1.75e-12).  A 1 % change of
    # γ, c or K fails by 1e-4 or more.
    assert np.abs(np.array(angles) - expected).max() < 1e-15
    # it turned back (overdamped: D/I = 230/s), or to the torque's τ/K = 0.02 rad
    assert abs(expected[-1] - tau / K) < 1e-9 and abs(expected[0] - expected[-1]) > 0.01


def _twin_runs(name: str, h: float, steps: int, pushed: bool = False) -> tuple[list, list]:
    """(compiled, numpy) (positions from the step's origin, orientations, angular
    velocities) of scene ``name`` after every step: the JointSim's kernel, and the same
    stepper's arrays stepped by reference_part.  ``pushed``: a force and a torque on the
    last bone from step 3 to 7 (their start and end restart BDF2)."""
    sc = likeforlike.scene(name)
    model = sc.model.with_options(h=h, integrator="bdf2")
    inputs = likeforlike.our_inputs(sc, h, steps)
    if pushed:
        force, torque = np.zeros((model.nbody, 3)), np.zeros((model.nbody, 3))
        force[-1], torque[-1] = (0.5, -1.0, 2.0), (0.02, 0.01, -0.03)
        inputs[3:8] = [StepInput(body_force=force, body_torque=torque)] * 5
    fast, slow = (JointSim(model, sc.start, handover=None) for _ in range(2))
    runs: tuple[list, list] = ([], [])
    for inp in inputs:
        fast.advance(inp)
        f, nb = fast._s, model.nbody
        runs[0].append((f.pos[:nb].copy(), f.quat[:nb].copy(), f.omega[:nb].copy()))
        assert slow._take_input(inp) is True
        parts = joint_space.parts(h, slow._s.clock[CLOCK_HPREV], slow._restart)
        slow._restart = False
        done = 0.0
        for length, ratio in parts:
            done += length
            joint_space.reference_part(slow._tree, slow._m, slow._s, length, ratio,
                                       slow._grip, h - done)  # fmt: skip
        s, nb = slow._s, model.nbody
        runs[1].append((s.pos[:nb].copy(), s.quat[:nb].copy(), s.omega[:nb].copy()))
    return runs


# measured: the doll pulled 2.3e-16; the chain at 100 ms (three parts a step) 7.5e-14; the
# released doll pushed for 5 steps 6.9e-15
@pytest.mark.parametrize(("name", "h", "pushed", "tol"),
                         [("doll-pull", 0.005, False, 1e-15), ("chain-bent", 0.1, False, 3e-13),
                          ("doll-bent", 0.005, True, 3e-14)])  # fmt: skip
def test_the_compiled_step_equals_the_dense_specification(name, h, pushed, tol):
    fast, slow = _twin_runs(name, h, 12, pushed)
    err = [max(np.abs(p - p2).max(), np.abs(q - q2).max(), np.abs(w - w2).max() * h)
           for (p, q, w), (p2, q2, w2) in zip(fast, slow, strict=True)]  # fmt: skip
    assert max(err) < tol, err
    moved = np.abs(fast[-1][0] - fast[0][0]).max()
    assert moved > 1e-3  # the scene moves


def test_a_released_chain_converges_to_the_truth_at_second_order():
    errors = []
    for h in (0.004, 0.002, 0.001):
        tips, truth, stepper = released_chain_tips(h, 0.2, joint_space=True)
        assert isinstance(stepper, JointSim)
        errors.append(np.linalg.norm(tips - truth, axis=1).max())
    ratios = np.array(errors[:-1]) / np.array(errors[1:])
    # measured: errors 1.65e-4, 4.16e-5, 1.02e-5 m; ratios 3.98 and 4.09 (the row step's
    # bdf2: 2.5e-4, 6.3e-5, 1.6e-5)
    assert np.all(ratios > 3.6), errors
    assert errors[-1] < 1.3e-5


def test_large_steps_stay_near_the_truth():
    # 250 ms steps, each in seven parts of 35.7 ms (joint_space.MAX_PART: 40 ms), over 2 s
    run = likeforlike.run_ours("chain-hanging", "bdf2", 0.25, repeats=1,
                               samples=likeforlike.LARGE, count_parts=True)  # fmt: skip
    # measured: 5.0 mm RMS at t = 1 and 2 s (14 mm at its worst); 28 parts a simulated
    # second, + the restart's 2 (over 2 s: 29)
    assert run.rms < 6e-3, run
    assert run.steps == 29.0, run


def test_inputs_it_cannot_take_hand_the_run_over():
    sc = likeforlike.scene("chain-bent")
    model = sc.model.with_options(h=0.005, integrator="bdf2")
    engine = Engine(model)
    sim = engine.stepper(sc.start)
    assert isinstance(sim, JointSim)
    for _ in range(10):
        sim.advance(None)
    held = sim.state.body_pos[2]
    pinned = StepInput(pins=(Pin(bone=2, point=np.zeros(3), target=held,
                                 target_quat=quat.IDENTITY),))  # fmt: skip
    before = sim.state
    sim.advance(pinned)
    oracle = Sim(engine.packed, before)
    oracle.advance(pinned)
    assert np.array_equal(sim.state.body_pos, oracle.state.body_pos)
    assert sim.report.solver != "joint-space" and sim.steps == 11
    sim.advance(None)
    oracle.advance(None)
    assert np.array_equal(sim.state.body_pos, oracle.state.body_pos)


def test_only_models_it_steps_exactly_are_stepped_in_joint_space():
    voigt = likeforlike.scene("doll-bent").model
    assert joint_space.unsupported(voigt.with_options(integrator="bdf2")) is None
    assert "euler" in joint_space.unsupported(voigt)
    assert "switched off" in joint_space.unsupported(
        voigt.with_options(integrator="bdf2", joint_space=False)
    )
    doll = scenes.doll_model().with_options(integrator="bdf2")  # plastic, limits, contacts
    assert joint_space.unsupported(doll) is not None
    assert not isinstance(Engine(doll).stepper(), JointSim)


def test_a_runaway_state_stops_with_the_step_and_the_bone():
    sc = likeforlike.scene("chain-bent")
    model = sc.model.with_options(h=0.005, integrator="bdf2", max_angular_speed=5.0)
    sim = Engine(model).stepper(sc.start)
    with pytest.raises(SimulationError, match=r"energy blow-up.*") as err:
        for _ in range(400):
            sim.advance(None)
    assert err.value.bone in model.body_names and err.value.step == sim.steps
