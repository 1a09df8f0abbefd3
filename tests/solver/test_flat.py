"""solver.compiled.flat: the packed model's arrays as views of a few buffers, rebuilt in
compiled code.  What the step sees must be exactly the arrays Python reads and writes
(fm.ws, fm.iopt …): same memory, same shapes, shared where pack shares them."""

from __future__ import annotations

from itertools import pairwise
from pathlib import Path

import numpy as np
import pytest
from rigbuild import chain

from puppetcli.rigfile import load_rig
from solver.compiled.flat import NLEAF, SCHEMA, flatten, unflatten
from solver.compiled.pack import pack
from solver.model import build_model

DOLL = Path(__file__).resolve().parents[2] / "rigs" / "doll.yaml"
PARTS = ("m", "g", "tree", "ptree", "ws", "pws", "opt", "iopt")


def leaves(x) -> list:
    return [a for y in x for a in leaves(y)] if isinstance(x, tuple) else [x]


@pytest.mark.parametrize(
    "model", [build_model(load_rig(DOLL)), build_model(chain(1, 0.01))], ids=["doll", "one bone"]
)
def test_compiled_views_are_the_python_views(model):
    fm = pack(model)  # kept alive: the compiled views returned here hold no reference
    python = leaves(tuple(getattr(fm, p) for p in PARTS))
    compiled = leaves(unflatten(fm.flat))
    assert len(python) == len(compiled) == NLEAF == len(fm.flat[-1])
    for a, b in zip(python, compiled, strict=True):
        assert (a.dtype, a.shape) == (b.dtype, b.shape)
        assert a.size == 0 or a.ctypes.data == b.ctypes.data
    fm.iopt[7] = 5
    assert unflatten(fm.flat)[7][7] == 5  # a write through the Python view reaches the step
    assert fm.ptree[5][0] is fm.tree[7][0]  # pack's sharing is kept


def test_views_hold_the_packed_values_and_do_not_overlap():
    model = build_model(load_rig(DOLL))
    fm = pack(model)
    assert np.array_equal(fm.m[17], model.body_inertia) and fm.opt[0] == model.options.h
    spans = {}
    for a in {id(a): a for a in leaves(tuple(getattr(fm, p) for p in PARTS))}.values():
        if a.size:
            spans.setdefault(a.base.ctypes.data, []).append(
                (a.ctypes.data, a.ctypes.data + a.nbytes)
            )
    for runs in spans.values():
        runs.sort()
        assert all(end <= start for (_, end), (start, _) in pairwise(runs))


def test_an_array_of_another_kind_is_refused():
    fm = pack(build_model(chain(2, 0.01)))
    parts = [getattr(fm, p) for p in PARTS]
    parts[0] = (*fm.m[:4], fm.m[4].astype(np.float32), *fm.m[5:])
    with pytest.raises(TypeError, match=r"\[0\]\[4\]: expected f3"):
        flatten(tuple(parts))
    assert len(SCHEMA) == len(PARTS)
