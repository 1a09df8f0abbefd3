"""solver.compiled.sim.Sim (in-place stepping) against fast_step, step by step: the same
kernel must give bit-identical states, and the steps it hands back (substeps, box–box
contacts, monitor failures) must end the same way."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from rigbuild import chain
from test_fast import doll_inputs

from puppetcli.bench.solvers import doll_scenes
from puppetcli.rig.load import load_rig
from solver.compiled.pack import pack
from solver.compiled.sim import Sim
from solver.engine import Engine
from solver.errors import SimulationError
from solver.model import build_model
from solver.state import StepInput, initial_state

DOLL = Path(__file__).resolve().parents[2] / "rigs" / "doll.yaml"
FIELDS = (
    "body_pos", "body_quat", "body_vel", "body_omega", "joint_q_sf", "joint_yielded",
    "joint_anchor", "joint_torque_avg", "joint_torque", "warm_key", "warm_lam",
)  # fmt: skip


def same(a, b) -> bool:
    return (a.time, a.step) == (b.time, b.step) and all(
        np.array_equal(getattr(a, f), getattr(b, f)) for f in FIELDS
    )


def lockstep(model, state, inputs) -> list:
    """Sim against fast_step, by ``step`` on even steps and ``advance`` on odd ones (its
    report and counts read afterwards)."""
    engine = Engine(model)
    sim, ref, reports = Sim(pack(model), state), state, []
    for k, inp in enumerate(inputs):
        ref, expected = engine.step(ref, inp)
        if k % 2:
            sim.advance(inp)
            got = sim.report
        else:
            got = sim.step(inp)
        assert (sim.contacts, sim.substeps) == (expected.contacts, expected.substeps)
        assert same(sim.state, ref), f"step {k}"
        assert (got.rows, got.solver, got.substeps) == (expected.rows, expected.solver,
                                                        expected.substeps)  # fmt: skip
        assert np.array_equal(got.grip_force, expected.grip_force)
        reports.append(got)
    return reports


def test_doll_with_grip_and_touch_is_identical():
    model = build_model(load_rig(DOLL)).with_options(h=0.001)
    state, inputs = doll_inputs(model, 300)
    reports = lockstep(model, state, inputs)
    assert max(np.abs(r.touch_force).max() for r in reports) > 1.0


def test_substeps_and_numpy_fallbacks_are_identical():
    rope = build_model(chain(40, 0.005, link=0.02, radius=0.005, masses=[0.02] * 40))
    assert max(r.substeps for r in lockstep(rope, initial_state(rope), [None] * 60)) > 1
    reference = build_model(chain(3, 0.01)).with_options(method="reference")  # all handed back
    lockstep(reference, initial_state(reference), [None] * 20)


def test_a_broken_simulation_raises_the_same_error():
    model = build_model(chain(3, 0.01)).with_options(max_speed=0.2)
    engine = Engine(model)
    sim, state = Sim(pack(model)), initial_state(model)
    with pytest.raises(SimulationError) as expected:
        for _ in range(100):
            state, _ = engine.step(state)
    with pytest.raises(SimulationError) as got:
        for _ in range(100):
            sim.step()
    assert str(got.value) == str(expected.value)


def test_a_state_of_another_model_is_refused():
    small, large = build_model(chain(3, 0.01)), build_model(chain(5, 0.01))
    with pytest.raises(ValueError, match="not a state of this model"):
        Sim(pack(small), initial_state(large))
    rest = initial_state(small)
    flat = replace(rest, body_vel=rest.body_vel[:, :1].copy())  # (nb, 1) would broadcast
    with pytest.raises(ValueError, match="not a state of this model"):
        Sim(pack(small), flat)


def test_two_sims_of_one_model_step_independently():
    # Each Sim has its own copy of the packed model and its workspaces: two of one model
    # stepped alternately, under different pushes, are each what it is alone.
    model = build_model(chain(5, 0.005))
    pushes = []
    for k in range(2):
        force = np.zeros((model.nbody, 3))
        force[-1] = (3.0 * (k + 1), 0.0, -2.0 * k)
        pushes.append(StepInput(body_force=force))
    together = [Sim(pack(model)), Sim(pack(model))]
    for _ in range(50):
        for sim, push in zip(together, pushes, strict=True):
            sim.advance(push)
    for sim, push in zip(together, pushes, strict=True):
        alone = Sim(pack(model))
        for _ in range(50):
            alone.advance(push)
        assert same(sim.state, alone.state)
    assert not same(together[0].state, together[1].state)


def test_a_doll_woken_by_a_push_falls_asleep_again_identically():
    # A Sim reuses its scratch arrays every step (kernel.step_arrays): the flags of the
    # bodies a step wakes ("fresh": their rest timer restarts) must not carry over into
    # the next, or a woken island would never fall asleep again.  The doll falls asleep
    # (3 s alone), one step's push wakes the right leg, which then settles and sleeps.
    model = doll_scenes()["doll"].with_options(h=0.005)
    engine = Engine(model)
    state = initial_state(model)
    for _ in range(600):
        state, _ = engine.step(state)
    assert state.body_asleep[1:].all()  # (the hips, clamped, never sleep: solver.advance.sleep)
    force = np.zeros((model.nbody, 3))
    force[model.body_names.index("shin_r")] = [5.0, 0.0, 0.0]
    inputs = [StepInput(body_force=force)] + [None] * 300
    lockstep(model, state, inputs)
    awake_after = []
    for inp in inputs:
        state, _ = engine.step(state, inp)
        awake_after.append(not state.body_asleep[1:].all())
    assert awake_after[0] and not awake_after[-1]  # woken, then asleep again
