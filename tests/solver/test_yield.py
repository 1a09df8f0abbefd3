"""Yielding: the low-pass filter on the joint torque and the threshold, by the recursion.

The model (solver/advance/rheology.py's docstring, Options.yield_filter_time): a joint
with a yield torque τ_y is a Voigt spring about its anchor until the low-passed norm of
its rheology torque,

    a_{k+1} = a_k + α (|τ_{k+1}| − a_k),   α = h / (T + h)     (backward Euler of T ȧ = |τ| − a),

exceeds τ_y; then it flows (the three-element row) until a_k falls below τ_y again.
Here a_k is recomputed from the torques the steps report, written out in the test, and
the flags are checked against the threshold at every step, on a bone pushed by a torque
ramping through τ_y and released, on both engines.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from rigbuild import one_bone

from solver.engine import Engine
from solver.model import build_model
from solver.spec import RheologySpec
from solver.state import StepInput, initial_state

H, YIELD, FILTER = 0.005, 2.0, 0.02


def run(engine: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(reported torque norms, filtered values, yield flags) after each step."""
    spec = one_bone(H, kf=20.0, df=2.0, dd=5.0)
    r = spec.bones[0].rheology
    bone = replace(spec.bones[0], rheology=RheologySpec(r.kf, r.df, r.dd, YIELD))
    spec = replace(spec, bones=(bone,))
    model = build_model(spec).with_options(engine=engine, sleep=False, yield_filter_time=FILTER)
    state = initial_state(model)
    engine_ = Engine(model)
    torque, avg, flags = [], [], []
    for k in range(150):  # 0.75 s: ramp to 1.3 τ_y over 0.5 s, then let go
        tau = 2.6 * YIELD * k * H if k * H < 0.5 else 0.0
        inp = StepInput(body_torque=np.array([[0.0, 0.0, tau]]))
        state, _ = engine_.step(state, inp)
        torque.append(np.linalg.norm(state.joint_torque[0]))
        avg.append(state.joint_torque_avg[0])
        flags.append(bool(state.joint_yielded[0]))
    return np.array(torque), np.array(avg), np.array(flags)


@pytest.mark.parametrize("engine", ["numpy", "compiled"])
def test_the_joint_yields_when_its_filtered_torque_passes_the_yield_torque(engine):
    torque, avg, flags = run(engine)
    alpha = H / (FILTER + H)
    expected = np.empty_like(avg)
    a = 0.0
    for k, tau in enumerate(torque):
        a = a + alpha * (tau - a)
        expected[k] = a
    # measured: 5e-16 N·m (the same sums in another order)
    np.testing.assert_allclose(avg, expected, rtol=0, atol=1e-13)
    assert flags.any() and not flags[-1]  # it yielded under load and recovered after
    # the flag turns at the threshold: on when a passes τ_y, off when it falls below
    before = np.concatenate(([False], flags[:-1]))
    np.testing.assert_array_equal(flags[~before], avg[~before] > YIELD)
    np.testing.assert_array_equal(~flags[before], avg[before] < YIELD)
