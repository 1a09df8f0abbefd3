"""solver.compiled.flat: the packed model's arrays as views of a few buffers, rebuilt in
compiled code.  What the step sees must be exactly the arrays Python reads and writes
(fm.ws, fm.iopt …): same memory, same shapes, shared where pack shares them; the generated
views are the layout's."""

from __future__ import annotations

from itertools import pairwise
from pathlib import Path

import numpy as np
import pytest
from rigbuild import chain

from puppetcli.rig.load import load_rig
from solver.compiled import layout
from solver.compiled.flat import flatten
from solver.compiled.layout import IOpt, Opt, Packed, leaf_count
from solver.compiled.pack import pack
from solver.compiled.views import packed_view
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
    compiled = leaves(packed_view(fm.flat, 0))
    assert len(python) == len(compiled) == leaf_count(Packed) == len(fm.flat[-1])
    for a, b in zip(python, compiled, strict=True):
        assert (a.dtype, a.shape) == (b.dtype, b.shape)
        assert a.size == 0 or a.ctypes.data == b.ctypes.data
    fm.iopt[IOpt.profiling] = 5
    assert packed_view(fm.flat, 0).iopt[IOpt.profiling] == 5  # a Python write reaches the step
    assert fm.ptree.work.block is fm.tree.work.block  # pack's sharing is kept


def test_views_hold_the_packed_values_and_do_not_overlap():
    model = build_model(load_rig(DOLL))
    fm = pack(model)
    assert np.array_equal(fm.m.body_inertia, model.body_inertia)
    assert fm.opt[Opt.h] == model.options.h and fm.opt[Opt.sleep_time] == model.options.sleep_time
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
    parts = fm.packed._replace(m=fm.m._replace(joint_kf=fm.m.joint_kf.astype(np.float32)))
    with pytest.raises(TypeError, match=r"\.m\.joint_kf: expected f3"):
        flatten(parts)
    with pytest.raises(TypeError, match=r"\.m: expected ModelArrays, got tuple"):
        flatten(fm.packed._replace(m=tuple(fm.m)))
    assert Packed._fields == PARTS


def test_the_views_are_generated_from_the_layout():
    """solver/compiled/views.py is what ``python -m solver.compiled.layout`` writes."""
    assert layout.VIEWS.read_text() == layout.views_source()
