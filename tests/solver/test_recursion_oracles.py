"""Gravity, mass and the warm start against values the solver does not compute.

- A free body under gravity and a constant force: semi-implicit Euler's exact discrete
  recursion, v_k = v_0 + k h a and x_n = x_0 + h Σ_{k=1..n} v_k = x_0 + h² a n(n+1)/2 with
  a = g + F/m, written out here (not the integrator's code), on the numpy step and the
  compiled one.  A 0.5 % error in gravity or in the mass moves x_n by 0.5 % of the fall
  (0.2 m here); the tolerance is 5e-14 m (measured: 4.9e-15 m).
- The warm start: each row starts from factor × last step's force of the row with the
  same key (0 for a new key), with factor 0.7, read from a dictionary here, for the
  numpy step's ``warm_start`` and the compiled step's ``_warm_fill``; and through whole
  steps of every path that starts from it (PGS, and the hybrid's iterated rows, on both
  engines): with no sweep the step's forces are its starting forces.
"""

from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest
from rigbuild import chain
from scipy.spatial.transform import Rotation
from test_kkt import grip_input
from test_massprops import capsule_profile, revolution
from test_solvers import contact_scene

from solver.engine import Engine
from solver.model import build_model
from solver.rows.table import KEY_SHIFT, KIND_CONTACT, KIND_FRICTION, KIND_LIMIT
from solver.solve.dispatch import warm_start
from solver.solve.dispatch_kernel import _warm_fill
from solver.state import StepInput, initial_state

H, STEPS = 0.01, 150
GRAVITY = np.array([0.0, -9.81, 0.0])
FORCE = np.array([3.0, 0.0, -1.5])  # N on a 1 kg link


@pytest.mark.parametrize("engine", ["numpy", "compiled"])
def test_free_body_follows_the_exact_discrete_recursion(engine):
    spec = chain(1, H, root_mode="free", gravity=GRAVITY)
    model = build_model(spec).with_options(engine=engine, sleep=False)
    mass = 1.0 / float(model.body_inv_mass[0])
    assert mass == pytest.approx(1.0)  # the link's mass as the rig gives it
    state = initial_state(model)
    x0 = state.body_pos[0].copy()
    force = np.zeros((model.nbody, 3))
    force[0] = FORCE
    inp = StepInput(body_force=force, body_torque=np.zeros((model.nbody, 3)))
    stepper = Engine(model).stepper(state)
    for _ in range(STEPS):
        stepper.advance(inp)
    a = GRAVITY + FORCE / 1.0  # the spec's mass, not the model's
    n = STEPS
    expected = x0 + H * H * a * n * (n + 1) / 2.0
    # measured: 4.9e-15 m and 2.3e-14 m/s on both steps (rounding over 150 steps)
    assert np.abs(stepper.state.body_pos[0] - expected).max() < 5e-14
    assert np.abs(stepper.state.body_vel[0] - n * H * a).max() < 1e-13


def _oracle(prev_keys, prev_lam, keys, factor):
    last = dict(zip(prev_keys.tolist(), prev_lam.tolist(), strict=True))
    return np.array([factor * last.get(k, 0.0) for k in keys.tolist()])


@pytest.fixture
def warm_case():
    rng = np.random.default_rng(3)
    prev_keys = np.sort(rng.choice(10_000, size=60, replace=False)).astype(np.int64)
    prev_lam = rng.normal(size=60)
    # this step: most keys again (a few swapped in order), some new ones
    keys = np.concatenate((prev_keys[:40], rng.choice(np.arange(10_000, 10_050), 10)))
    keys[[3, 4]] = keys[[4, 3]]
    return prev_keys, prev_lam, keys.astype(np.int64)


def test_numpy_warm_start_is_factor_times_last_force_by_key(warm_case):
    prev_keys, prev_lam, keys = warm_case
    model = SimpleNamespace(options=SimpleNamespace(warm_start=True, warm_start_factor=0.7))
    state = SimpleNamespace(warm_key=prev_keys, warm_lam=prev_lam)
    lam0 = warm_start(model, state, _Rows(keys))
    np.testing.assert_array_equal(lam0, _oracle(prev_keys, prev_lam, keys, 0.7))


def test_compiled_warm_start_is_factor_times_last_force_by_key(warm_case):
    prev_keys, prev_lam, keys = warm_case
    lam = np.full(len(keys) + 3, np.nan)
    lam[: len(keys)] = 0.0
    _warm_fill(0.7, prev_keys, prev_lam, keys, len(keys), lam)
    np.testing.assert_array_equal(lam[: len(keys)], _oracle(prev_keys, prev_lam, keys, 0.7))
    assert np.isnan(lam[len(keys) :]).all()  # nothing past the rows written


class _Rows:
    """The rows' keys, as ``warm_start`` reads them."""

    def __init__(self, key: np.ndarray) -> None:
        self.key = key

    def __len__(self) -> int:
        return len(self.key)


@pytest.mark.parametrize("engine", ["numpy", "compiled"])
@pytest.mark.parametrize("method", ["pgs", "hybrid"])
def test_a_step_without_sweeps_keeps_factor_times_last_force(engine, method):
    # A scene with contacts, friction, limits and a saturated grip, one step solved, then a
    # step with no PGS sweep and factor 0.7: every warm-started row keeps 0.7 × its last
    # force (bounds hold: the scaled forces stay in the friction pyramid and the grip's
    # limit).  PGS starts every row from it; the hybrid its iterated rows (limits,
    # contacts, friction), solving the joint and grip rows exactly.
    model, state = contact_scene(1)
    inp = grip_input(model, state, 0.3)
    run = model.with_options(engine=engine, method=method, sleep=False, max_substeps=1)
    first, _ = Engine(run.with_options(iterations=50)).step(state, inp)
    warm = run.with_options(iterations=0, warm_start_factor=0.7)
    second, report = Engine(warm).step(first, inp)
    assert report.iterations == 0
    expected = _oracle(first.warm_key, first.warm_lam, second.warm_key, 0.7)
    kind = second.warm_key >> KEY_SHIFT
    started = np.isin(kind, [KIND_LIMIT, KIND_CONTACT, KIND_FRICTION]) | (method == "pgs")
    assert started.sum() > 10 and np.any(expected[started] != 0.0)
    np.testing.assert_array_equal(second.warm_lam[started], expected[started])


def _spinning(engine: str, shape: str, omega: np.ndarray, steps: int, h: float):
    """The states of a free link without gravity spun at ``omega`` (rad/s, world)."""
    spec = chain(1, h, root_mode="free", gravity=(0.0, 0.0, 0.0), shape=shape, radius=0.03)
    model = build_model(spec).with_options(engine=engine, sleep=False)
    state = replace(initial_state(model), body_omega=omega[None, :])
    stepper = Engine(model).stepper(state)
    states = [stepper.state]
    for _ in range(steps):
        stepper.advance()
        states.append(stepper.state)
    return states


@pytest.mark.parametrize("engine", ["numpy", "compiled"])
def test_a_spinning_ball_turns_by_exactly_n_h_omega(engine):
    # A ball's inertia is isotropic: torque-free, ω stays and after n steps the body has
    # turned by exp(n h ω) from where it started (the rotation vector's exponential
    # computed by scipy, composed on the left: a world-frame rate).
    omega = np.array([1.3, -2.1, 0.7])
    states = _spinning(engine, "sphere", omega, 200, 0.005)
    q0 = Rotation.from_quat(states[0].body_quat[0], scalar_first=True)
    for n in (1, 37, 200):
        expected = (Rotation.from_rotvec(n * 0.005 * omega) * q0).as_quat(scalar_first=True)
        got = states[n].body_quat[0]
        # measured at n = 200 (rounding of 200 products): 5.9e-15, ω 2.3e-14 rad/s
        assert np.abs(got * np.sign(got @ expected) - expected).max() < 3e-14
        np.testing.assert_allclose(states[n].body_omega[0], omega, rtol=0, atol=1e-13)


@pytest.mark.parametrize("engine", ["numpy", "compiled"])
def test_a_spinning_capsule_precesses_about_its_momentum_at_the_closed_form_rate(engine):
    # Torque-free, axisymmetric (I⊥, I⊥, I_a about the link's axis e): L is constant and
    # e turns about L at the rate |L|/I⊥ (Euler's free precession).  I⊥ and I_a come from
    # the integrals of test_massprops, not the model.  The step's midpoint rotation is
    # second order: the error after 1 s is 1.09e-7 at h = 2 ms, 2.71e-8 at 1 ms (measured,
    # both engines: 4.0× when h halves).
    volume, axial, perp = revolution(capsule_profile(0.03, 0.1), 0.05 + 0.03)
    inertia_perp = perp / volume  # the link's mass is 1 kg
    omega0 = np.array([0.5, 6.0, -1.0])  # world; the link lies along x at rest
    e0 = np.array([1.0, 0.0, 0.0])
    momentum = inertia_perp * omega0 + (axial / volume - inertia_perp) * (omega0 @ e0) * e0
    h, steps = 0.002, 500
    states = _spinning(engine, "capsule", omega0, steps, h)
    rate = np.linalg.norm(momentum) / inertia_perp
    turn = Rotation.from_rotvec(rate * h * steps * momentum / np.linalg.norm(momentum))
    e_step = Rotation.from_quat(states[-1].body_quat[0], scalar_first=True).apply(e0)
    assert np.linalg.norm(e_step - turn.apply(e0)) < 5e-7
