"""The Python around the compiled step (solver.compiled.fast.fast_step): the States and reports it
builds cheaply are the ones the ordinary constructors build."""

from __future__ import annotations

import dataclasses

import numpy as np

import solver.compiled.fast as fast
from solver.compiled.fast import FIELDS, HISTORY_FIELDS, SOLVER_NAMES, _successor, kernel_report
from solver.compiled.layout import ReportFloat, StateSet
from solver.state import State, StepReport


def same(got, want) -> bool:
    if type(got) is not type(want) or vars(got).keys() != vars(want).keys():
        return False
    for name, value in vars(want).items():
        mine = getattr(got, name)
        if isinstance(value, np.ndarray):
            if not (mine.dtype == value.dtype and np.array_equal(mine, value)):
                return False
        elif mine != value or type(mine) is not type(value):
            return False
    return repr(got) == repr(want)


def test_kernel_fields_are_state_fields():
    names = [f.name for f in dataclasses.fields(State)]
    assert names[: 2 + len(FIELDS)] == ["time", "step", *FIELDS]
    assert [f.name for f in dataclasses.fields(StepReport)] == list(fast._REPORT_FIELDS)
    # the cheap constructions are in use (else fast_step is ~3 µs slower a step)
    assert fast._STATE_REST is not None and fast._DIRECT_REPORT


def _history() -> tuple:
    """A StateSet's history arrays (prev_x … prev_q_sf, hist) of distinct values."""
    return (*(np.full(2, 20.0 + k) for k in range(5)), np.array([0.005, 1.5, 2.5]))


def test_states_and_reports_are_the_constructors():
    arrays = tuple(np.full(k + 1, float(k)) for k in range(len(FIELDS)))
    # State's order: x … τ, warm keys and λ, sleep; then the StateSet's history
    out = StateSet(*arrays[:9], *arrays[11:], *_history())
    got = _successor(State(0.0, 0, *arrays), 0.5, 3, out, *arrays[9:11], False)
    assert same(got, State(0.5, 3, *arrays))
    assert dataclasses.replace(got, step=4).step == 4
    got = _successor(State(0.0, 0, *arrays), 0.5, 3, out, *arrays[9:11], True)
    prev = dict(zip(HISTORY_FIELDS, _history(), strict=False))
    assert same(got, State(0.5, 3, *arrays, **prev, prev_h=0.005, prev_mark=1.5, prev_load=2.5))
    rep_f, at = np.arange(10.0), ReportFloat
    got = kernel_report(np.array([108, 2, 15, 1, 3]), rep_f)
    force, torque = rep_f[at.grip_force : at.grip_torque], rep_f[at.grip_torque : at.touch_force]
    want = StepReport(108, 2, 15, 0.0, SOLVER_NAMES[1], force, torque, rep_f[at.touch_force :],
                      substeps=3)  # fmt: skip
    assert same(got, want)


def test_a_state_subclass_keeps_its_fields():
    @dataclasses.dataclass(frozen=True)
    class Tagged(State):
        tag: str = ""

    arrays = tuple(np.full(2, float(k)) for k in range(len(FIELDS)))
    out = StateSet(*arrays[:9], *arrays[11:], *_history())
    got = _successor(Tagged(0.0, 0, *arrays, tag="a"), 0.5, 1, out, *arrays[9:11], False)
    assert type(got) is Tagged and got.tag == "a" and got.time == 0.5
