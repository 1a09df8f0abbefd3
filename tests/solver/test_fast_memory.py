"""The compiled step frees every array it makes, and nothing twice.

Most of the step runs without numba's reference counting (solver.compiled.kernel._step,
``_nrt=False``), between functions that keep it (the allocation of the step's arrays,
the projection, the substep test, sleeping, a Schur complement too large for the
step's scratch): an array handed the wrong way
across that boundary would leak, or be freed while still in use.  numba's runtime
counts its own allocations and frees (its NRT statistics); over each run below, both
must grow by the same amount, through ``Sim`` (in place) and ``fast_step`` (fresh
states, dropped afterwards).  The runs cover the hybrid, PGS and direct solves, the grip,
a touching pointer, sleeping, the joint projection, a chain lying on the ground (more
iterated rows than the scratch holds) and steps handed back to numpy."""

from __future__ import annotations

import gc
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from numba.core.runtime import _nrt_python, rtsys
from rigbuild import chain
from test_fast import box_stack, doll_inputs, lying_chain

from puppetcli.rig.load import load_rig
from solver.compiled.pack import pack
from solver.compiled.sim import Sim
from solver.engine import Engine
from solver.model import build_model
from solver.state import initial_state

DOLL = Path(__file__).resolve().parents[2] / "rigs" / "doll.yaml"


def _doll(method: str, steps: int):
    model = build_model(load_rig(DOLL)).with_options(h=0.001, method=method)
    return (model, *doll_inputs(model, steps))


def _tumbling_chain():
    spec = chain(4, 0.01, root_mode="free", gravity=(0, 0, 0), lengths=[0.3, 0.1, 0.4, 0.2])
    model = build_model(spec)
    omega = np.random.default_rng(0).normal(scale=3.0, size=(4, 3))
    return model, replace(initial_state(model), body_omega=omega), [None] * 50


def _rope():
    model = build_model(chain(40, 0.005, link=0.02, radius=0.005, masses=[0.02] * 40))
    return model, initial_state(model), [None] * 30


def _boxes():
    model = build_model(box_stack(0.4)).with_options(h=0.005)  # box–box; sleeper under a box
    return model, initial_state(model), [None] * 200


def _reference():
    model = build_model(chain(3, 0.01)).with_options(method="reference")  # all handed back
    return model, initial_state(model), [None] * 20


def _lying_chain():
    return (*lying_chain(), [None] * 10)


SCENES = {
    "doll-auto": lambda: _doll("auto", 200),
    "doll-pgs": lambda: _doll("pgs", 100),
    "doll-hybrid": lambda: _doll("hybrid", 100),
    "chain-direct-projection": _tumbling_chain,
    "rope-substeps": _rope,
    "boxes": _boxes,
    "reference-handed-back": _reference,
    "schur-beyond-scratch": _lying_chain,
}


def _counts() -> tuple[int, int]:
    s = rtsys.get_allocation_stats()
    return s.alloc - s.free, s.mi_alloc - s.mi_free


def _run(model, state, inputs) -> None:
    engine = Engine(model)
    sim = Sim(pack(model), state)
    for inp in inputs:
        sim.advance(inp)
    for inp in inputs:
        state, _ = engine.step(state, inp)


@pytest.mark.parametrize("name", sorted(SCENES))
def test_every_array_the_step_makes_is_freed_once(name):
    _nrt_python.memsys_enable_stats()
    model, state, inputs = SCENES[name]()
    _run(model, state, inputs[:3])  # compiled or loaded before counting
    gc.collect()
    before = _counts()
    _run(model, state, inputs)
    gc.collect()
    after = _counts()
    assert after == before, f"{name}: (allocations − frees, meminfos made − freed) moved"
    stats = rtsys.get_allocation_stats()
    assert stats.alloc > 0 and stats.free > 0  # the counters are live (not a vacuous 0 = 0)
