"""Gravity, mass and the warm start against values the solver does not compute.

- A free body under gravity and a constant force: semi-implicit Euler's exact discrete
  recursion, v_k = v_0 + k h a and x_n = x_0 + h Σ_{k=1..n} v_k = x_0 + h² a n(n+1)/2 with
  a = g + F/m, written out here (not the integrator's code), on the numpy step and the
  compiled one.  A 0.5 % error in gravity or in the mass moves x_n by 0.5 % of the fall
  (0.2 m here); the tolerance is 5e-14 m (measured: 4.9e-15 m).
- The warm start: each row starts from factor × last step's force of the row with the
  same key (0 for a new key), with factor 0.7, read from a dictionary here, for the
  numpy step's ``warm_start`` and the compiled step's ``_warm_fill``.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from rigbuild import chain

from solver.engine import Engine
from solver.model import build_model
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
