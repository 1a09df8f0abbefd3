"""The trouble monitor names the body that broke, not a fixed one dragged along."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from puppetcli.rig.load import load_rig
from solver.advance.monitor import check_state
from solver.errors import SimulationError
from solver.model import build_model
from solver.state import initial_state

DOLL = Path(__file__).resolve().parents[2] / "rigs" / "doll.yaml"


@pytest.fixture(scope="module")
def doll():
    model = build_model(load_rig(DOLL))
    root = int(np.flatnonzero(model.body_inv_mass == 0.0)[0])  # the hips on their stand
    return model, root


def _check_with_broken(model, bodies: list[int], value: float) -> None:
    state = initial_state(model)
    pos = state.body_pos.copy()
    pos[bodies] = value
    vel = np.hstack((state.body_vel, state.body_omega))
    check_state(model, 7, 0.035, pos, state.body_quat, vel)


@pytest.mark.parametrize("value", [np.nan, np.inf])
def test_non_finite_names_the_movable_body_over_the_fixed_root(doll, value):
    model, root = doll
    arm = model.body_names.index("forearm_l")
    with pytest.raises(SimulationError) as err:
        _check_with_broken(model, [root, arm], value)
    assert root < arm and err.value.bone == "forearm_l" and err.value.step == 7


def test_a_broken_fixed_body_alone_is_still_named(doll):
    model, root = doll
    with pytest.raises(SimulationError) as err:
        _check_with_broken(model, [root], np.nan)
    assert err.value.bone == model.body_names[root]


def test_the_rest_state_passes(doll):
    model, _ = doll
    _check_with_broken(model, [], np.nan)  # nothing broken: no error
