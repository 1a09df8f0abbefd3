"""Each skip of unneeded work (Options.cull_pairs, Options.dormant_rows,
Options.leaf_contacts, auto's direct solve) against the path without it: the same states,
within the solver's tolerance."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from rigbuild import chain
from test_fast import doll_inputs

from puppetcli.rig.load import load_rig
from solver.engine import Engine
from solver.model import build_model
from solver.state import initial_state

DOLL = Path(__file__).resolve().parents[2] / "rigs" / "doll.yaml"


def run(engine, model, state, inputs):
    """The states and reports of ``model`` stepped through ``inputs`` on ``engine``
    ("compiled" or "numpy": Options.engine)."""
    stepper = Engine(model.with_options(engine=engine))
    states, reports = [], []
    for inp in inputs:
        state, report = stepper.step(state, inp)
        states.append(state)
        reports.append(report)
    return states, reports


def largest_difference(a, b) -> float:
    return max(
        max(np.abs(x.body_pos - y.body_pos).max(), np.abs(x.body_vel - y.body_vel).max())
        for x, y in zip(a, b, strict=True)
    )


@pytest.mark.parametrize("skip", ["cull_pairs", "dormant_rows"])
@pytest.mark.parametrize("engine", ["compiled", "numpy"])
def test_skipping_changes_nothing_on_the_doll(skip, engine):
    # The doll with ground contacts, a push and a grip, then a free-mode pointer pressing
    # the forearm: pairs far apart would find no contact in the narrow phase, and dormant
    # rows stay at λ = 0 in the unskipped iteration too.
    steps = 300 if engine == "compiled" else 60
    model = build_model(load_rig(DOLL)).with_options(h=0.001)
    state, inputs = doll_inputs(model, steps)
    on, rep_on = run(engine, model, state, inputs)
    off, rep_off = run(engine, model.with_options(**{skip: False}), state, inputs)
    assert largest_difference(on, off) <= 1e-12  # measured 0, but 2.4e-13 (numpy, dormant)
    assert [r.contacts for r in rep_on] == [r.contacts for r in rep_off]
    assert max(r.contacts for r in rep_on) > 0


def test_dormant_rows_are_really_left_out_and_checked():
    # The skip must do something: the doll's speculative foot contacts are dormant, so
    # with the skip on the hybrid iterates fewer rows (fewer sweeps) for the same result.
    model = build_model(load_rig(DOLL)).with_options(h=0.001)
    state = initial_state(model)
    inputs = [None] * 50
    _, on = run("compiled", model, state, inputs)
    _, off = run("compiled", model.with_options(dormant_rows=False), state, inputs)
    assert min(r.contacts for r in on) > 0
    assert sum(r.iterations for r in on) < sum(r.iterations for r in off)


@pytest.mark.parametrize("engine", ["compiled", "numpy"])
def test_leaf_contacts_agree_with_the_iteration_and_save_its_sweeps(engine):
    # A chain of balls resting on the ground: with the skip its contacts stick in the
    # forest, solved exactly, and nothing is iterated after the first step (whose
    # contacts, not pushing before it, start iterated); without it PGS on their Schur
    # complement approaches the same rest as its sweeps grow, slowly: the redundant
    # resting contacts leave it crawling (solver residual ~5e-9 after 15 to 3,000 sweeps).
    spec = chain(8, 0.001, root_mode="free", ground=0.98, collide=True, shape="sphere")
    model = build_model(spec).with_options(sleep=False)
    state, inputs = initial_state(model), [None] * 100
    exact, on = run(engine, model, state, inputs)
    assert min(r.contacts for r in on) == 8 and sum(r.iterations for r in on[1:]) == 0
    gaps = []
    for sweeps in (15, 300):
        iterated, reports = run(engine, model.with_options(leaf_contacts=False, iterations=sweeps),
                                state, inputs)  # fmt: skip
        assert min(r.iterations for r in reports) == sweeps
        gaps.append(largest_difference(exact, iterated))
    assert gaps[0] < 1e-8  # m and m/s over 0.1 s: measured 3.56e-9 (both engines)
    assert gaps[1] < gaps[0]  # measured 3.52e-9: closer with more sweeps


def test_direct_solve_agrees_with_converged_pgs_on_two_sided_rows():
    # auto solves the doll without ground and limits exactly; the paper's PGS reaches the
    # same motion only when its sweeps converge (300 sweeps: within 2.1e-12 over 0.1 s;
    # 15 sweeps: 1.7e-3).
    spec = load_rig(DOLL)
    bare = replace(
        spec,
        ground=None,
        bones=tuple(replace(b, limits=type(b.limits)(), collide=False) for b in spec.bones),
    )
    model = build_model(bare).with_options(h=0.001)
    state, inputs = doll_inputs(model, 200)
    inputs = inputs[:100]
    exact, reports = run("compiled", model, state, inputs)
    assert {r.solver for r in reports} == {"direct"}
    pgs, _ = run("compiled", model.with_options(method="pgs", iterations=300), state, inputs)
    assert largest_difference(exact, pgs) < 1e-11
    pgs15, _ = run("compiled", model.with_options(method="pgs", iterations=15), state, inputs)
    assert largest_difference(exact, pgs15) > largest_difference(exact, pgs)
