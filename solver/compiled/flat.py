"""A FastModel's static arrays stored in a few buffers, rebuilt as views in compiled code.

The compiled step takes eight nested tuples of about a hundred arrays (``solver.compiled.pack``:
model, geometry, forest, workspaces, options).  Passing them from Python costs numba ~0.1
µs of unboxing per array on every call (~13 µs a step); a view made inside compiled code
costs a few ns and no Python object.  So ``flatten`` copies every leaf into one buffer per
kind of leaf and hands back the same nested tuples of views (what Python code reads and
writes: ``fm.ws[10]``, ``fm.iopt[7] = 1``), and ``unflatten`` rebuilds those tuples from
the buffers in compiled code, sharing their memory.

    flat = (f (·,), f3 (·,3), f4 (·,4), f6 (·,6), f33 (·,3,3), f66 (·,6,6) float64,
            i (·,), i6 (·,6) int64, b (·,) bool, layout (nleaf, 2) int64)

A leaf is a run of rows of the buffer of its kind (its dtype and trailing shape), so its
view needs no reshape (~70 ns each in numba).  layout holds each leaf's (offset, rows), in
depth-first order of SCHEMA.  The compiled views are ``numba.carray``s over the buffer's
memory that hold no reference to it: a slice would, and its reference counting across
the rebuild's calls costs ~45 ns a view (5 µs a step); without it a view costs a few ns.
So the caller keeps the buffers alive for the call (Python holds ``fm.flat``), and no
compiled function may return one of these views to Python.  ``unflatten`` and the functions that
build its parts are inlined into their caller (``inline="always"``): made in a function
of their own, the hundred views were returned as one tuple, a few kilobytes of array
structs copied out of it on every step (the one-joint creep step at 1 ms: 7.0 → 3.5 µs
a kernel call; docs/performance.md).  An array that appears twice
(ptree's arrays are tree's) is stored once and both rows point at it.  ``unflatten`` is
written out by hand for SCHEMA (numba can neither loop over a heterogeneous tuple nor
cache generated code); ``flatten`` checks the arrays it is given against SCHEMA, so the
two cannot drift apart silently.
"""

from __future__ import annotations

import numpy as np
from llvmlite import ir
from numba import carray, types
from numba.core import cgutils
from numba.extending import intrinsic
from numba.np.arrayobj import make_array

from solver.jit import kernel

BUFFERS = {
    "f": (np.float64, ()), "f3": (np.float64, (3,)), "f4": (np.float64, (4,)),
    "f6": (np.float64, (6,)), "f33": (np.float64, (3, 3)), "f66": (np.float64, (6, 6)),
    "i": (np.int64, ()), "i6": (np.int64, (6,)), "b": (np.bool_, ()),
}  # fmt: skip
"""Leaf kinds, in the order of flat's buffers: dtype and the shape after the first axis."""

_ROWS = ("i", "i", "f6", "f6", "f", "f", "f", "f", "i", "f", "i", "i")
_CONTACTS = ("i", "i", "f3", "f3", "f", "f", "i")
_TREE_WS = ("f66", "f66", "f6", "f6")
SCHEMA = (
    ("i", "i", "f3", "f3", "f3", "f3", "f3", "b", "f3", "f", "f", "f", "f", "b", "b", "f",
     "f", "f33", "f33", "i", "f6", "f3"),  # m
    ("i", "f3", "f4", "i", "f", "f3", "f", "i", "i", "i", "f", "i", "i", "f", "i", "f"),  # g
    ("i", "i", "i", "i", "i", "i6", "i", _TREE_WS),  # tree
    ("i", "i", "i", "i6", "i", _TREE_WS),  # ptree
    (_ROWS, "f6", "f6", "i", _CONTACTS, "f33", "f33", "f33", "f3", "f33", "i"),  # ws
    (_ROWS, "f6", "f6", "f33", "f33", "f33", "f"),  # pws
    "f",  # opt
    "i",  # iopt
)  # fmt: skip
"""The kind of every leaf of (m, g, tree, ptree, ws, pws, opt, iopt) (pack's layouts)."""

ALIGN = 8  # rows: every leaf starts on a 64-byte boundary of its buffer


def _count(schema) -> int:
    return 1 if isinstance(schema, str) else sum(_count(s) for s in schema)


def _starts(schema) -> tuple[int, ...]:
    """First leaf of each part of SCHEMA."""
    sizes = [_count(s) for s in schema]
    return tuple(int(k) for k in np.cumsum([0, *sizes[:-1]]))


_M, _G, _TREE, _PTREE, _WS, _PWS, _OPT, _IOPT = _starts(SCHEMA)
NLEAF = _count(SCHEMA)


def _leaves(x, schema, path: str = "") -> list:
    """[(array, kind)] of x in depth-first order, checked against schema."""
    if isinstance(schema, str):
        dtype, trail = BUFFERS[schema]
        ok = isinstance(x, np.ndarray) and x.dtype == dtype and x.ndim == 1 + len(trail)
        if not (ok and x.shape[1:] == trail and x.flags.c_contiguous):
            got = f"{x.dtype} {x.shape}" if isinstance(x, np.ndarray) else type(x).__name__
            raise TypeError(f"packed array {path or '.'}: expected {schema}, got {got}")
        return [(x, schema)]
    if not (isinstance(x, tuple) and len(x) == len(schema)):
        raise TypeError(f"packed tuple {path or '.'}: expected {len(schema)} entries")
    pairs = enumerate(zip(x, schema, strict=True))
    return [leaf for k, (y, s) in pairs for leaf in _leaves(y, s, f"{path}[{k}]")]


def _replace(x, views: dict):
    return tuple(_replace(y, views) for y in x) if isinstance(x, tuple) else views[id(x)]


def flatten(parts: tuple, schema: tuple = SCHEMA) -> tuple[tuple, tuple]:
    """(flat, views): ``parts`` (nested tuples of arrays as ``schema``) copied into the
    buffers of ``flat`` (module docstring), and the same nested tuples of views into them."""
    leaves = _leaves(parts, schema)
    slots: dict[int, int] = {}  # id(array) → offset in its kind's buffer
    used = dict.fromkeys(BUFFERS, 0)
    for a, kind in leaves:
        if id(a) not in slots:
            slots[id(a)] = used[kind]
            used[kind] += -(-len(a) // ALIGN) * ALIGN
    bufs = {k: np.zeros((used[k], *trail), dtype) for k, (dtype, trail) in BUFFERS.items()}
    layout = np.zeros((len(leaves), 2), np.int64)
    views: dict[int, np.ndarray] = {}
    for n, (a, kind) in enumerate(leaves):
        offset = slots[id(a)]
        layout[n] = offset, len(a)
        if id(a) not in views:
            views[id(a)] = bufs[kind][offset : offset + len(a)]
            views[id(a)][...] = a
    return (*bufs.values(), layout), _replace(parts, views)


@intrinsic
def _row_pointer(typingctx, buf, row):
    """The address of row ``row`` of buf (C-contiguous), as a typed pointer."""

    def codegen(context, builder, signature, args):
        ary = make_array(signature.args[0])(context, builder, args[0])
        stride = cgutils.unpack_tuple(builder, ary.strides, signature.args[0].ndim)[0]
        raw = builder.bitcast(ary.data, ir.IntType(8).as_pointer())
        at = builder.gep(raw, [builder.mul(args[1], stride)])
        return builder.bitcast(at, ary.data.type)

    return types.CPointer(buf.dtype)(buf, row), codegen


@kernel(_nrt=True)  # returns views: never without NRT (kernel._step)
def leaf(buf, lay, k):
    """Leaf k (layout lay): its rows of buf, as an array that holds no reference to buf
    (module docstring)."""
    return carray(_row_pointer(buf, lay[k, 0]), (lay[k, 1],) + buf.shape[1:])


@kernel(_nrt=True)  # returns a view: never without NRT (kernel._step)
def square(buf, n):
    """The first n² entries of buf (1-D, C-contiguous) as an (n, n) array that holds no
    reference to buf (module docstring: the caller keeps buf alive)."""
    return carray(_row_pointer(buf, 0), (n, n))


@kernel(inline="always")  # views made in the caller (module docstring)
def _model(flat, k):
    """m (pack): joints' indices, anchors, gains, limits, yield; bodies' mass, inertia,
    island; joints' tension levers and limit thresholds."""
    f, f3, _, f6, f33, _, i, _, b, lay = flat
    return (
        leaf(i, lay, k), leaf(i, lay, k + 1), leaf(f3, lay, k + 2), leaf(f3, lay, k + 3),
        leaf(f3, lay, k + 4), leaf(f3, lay, k + 5), leaf(f3, lay, k + 6), leaf(b, lay, k + 7),
        leaf(f3, lay, k + 8), leaf(f, lay, k + 9), leaf(f, lay, k + 10), leaf(f, lay, k + 11),
        leaf(f, lay, k + 12), leaf(b, lay, k + 13), leaf(b, lay, k + 14), leaf(f, lay, k + 15),
        leaf(f, lay, k + 16), leaf(f33, lay, k + 17), leaf(f33, lay, k + 18),
        leaf(i, lay, k + 19), leaf(f6, lay, k + 20), leaf(f3, lay, k + 21),
    )  # fmt: skip


@kernel(inline="always")  # views made in the caller (module docstring)
def _geometry(flat, k):
    """g (pack): shapes, then candidate pairs, then the pointer-touchable shapes."""
    f, f3, f4, _, _, _, i, _, _, lay = flat
    return (
        leaf(i, lay, k), leaf(f3, lay, k + 1), leaf(f4, lay, k + 2), leaf(i, lay, k + 3),
        leaf(f, lay, k + 4), leaf(f3, lay, k + 5), leaf(f, lay, k + 6), leaf(i, lay, k + 7),
        leaf(i, lay, k + 8), leaf(i, lay, k + 9), leaf(f, lay, k + 10), leaf(i, lay, k + 11),
        leaf(i, lay, k + 12), leaf(f, lay, k + 13), leaf(i, lay, k + 14), leaf(f, lay, k + 15),
    )  # fmt: skip


@kernel(inline="always")  # views made in the caller (module docstring)
def _tree_ws(flat, k):
    """The elimination's block workspace (D, Y, w, g)."""
    f6, f66, lay = flat[3], flat[5], flat[9]
    return leaf(f66, lay, k), leaf(f66, lay, k + 1), leaf(f6, lay, k + 2), leaf(f6, lay, k + 3)


@kernel(inline="always")  # views made in the caller (module docstring)
def _tree(flat, k):
    """tree (pack._forest): order, parents, rheology rows, sequence, node rows, workspace."""
    i, i6, lay = flat[6], flat[7], flat[9]
    return (
        leaf(i, lay, k), leaf(i, lay, k + 1), leaf(i, lay, k + 2), leaf(i, lay, k + 3),
        leaf(i, lay, k + 4), leaf(i6, lay, k + 5), leaf(i, lay, k + 6), _tree_ws(flat, k + 7),
    )  # fmt: skip


@kernel(inline="always")  # views made in the caller (module docstring)
def _ptree(flat, k):
    """ptree (pack._forest): the projection's forest (tree's arrays, no rheology rows)."""
    i, i6, lay = flat[6], flat[7], flat[9]
    return (
        leaf(i, lay, k), leaf(i, lay, k + 1), leaf(i, lay, k + 2), leaf(i6, lay, k + 3),
        leaf(i, lay, k + 4), _tree_ws(flat, k + 5),
    )  # fmt: skip


@kernel(inline="always")  # views made in the caller (module docstring)
def _rows(flat, k):
    """A row table (pack._rows, solver.rows.table_kernel.set_row), leaves k … k + 11."""
    f, f6, i, lay = flat[0], flat[3], flat[6], flat[9]
    return (
        leaf(i, lay, k), leaf(i, lay, k + 1), leaf(f6, lay, k + 2), leaf(f6, lay, k + 3),
        leaf(f, lay, k + 4), leaf(f, lay, k + 5), leaf(f, lay, k + 6), leaf(f, lay, k + 7),
        leaf(i, lay, k + 8), leaf(f, lay, k + 9), leaf(i, lay, k + 10), leaf(i, lay, k + 11),
    )  # fmt: skip


@kernel(inline="always")  # views made in the caller (module docstring)
def _contacts(flat, k):
    """Contact buffers (pack._contacts): body_a, body_b, point, normal, depth, friction, key."""
    f, f3, i, lay = flat[0], flat[1], flat[6], flat[9]
    return (
        leaf(i, lay, k), leaf(i, lay, k + 1), leaf(f3, lay, k + 2), leaf(f3, lay, k + 3),
        leaf(f, lay, k + 4), leaf(f, lay, k + 5), leaf(i, lay, k + 6),
    )  # fmt: skip


@kernel(inline="always")  # views made in the caller (module docstring)
def _ws(flat, k):
    """ws (pack): rows, responses, rheology joints, contacts, frames, shapes, profile."""
    f3, f6, f33, i, lay = flat[1], flat[3], flat[4], flat[6], flat[9]
    return (
        _rows(flat, k), leaf(f6, lay, k + 12), leaf(f6, lay, k + 13), leaf(i, lay, k + 14),
        _contacts(flat, k + 15), leaf(f33, lay, k + 22), leaf(f33, lay, k + 23),
        leaf(f33, lay, k + 24), leaf(f3, lay, k + 25), leaf(f33, lay, k + 26), leaf(i, lay, k + 27),
    )  # fmt: skip


@kernel(inline="always")  # views made in the caller (module docstring)
def _pws(flat, k):
    """pws (pack): the projection's rows, responses, frames and λ."""
    f, f6, f33, lay = flat[0], flat[3], flat[4], flat[9]
    return (
        _rows(flat, k), leaf(f6, lay, k + 12), leaf(f6, lay, k + 13), leaf(f33, lay, k + 14),
        leaf(f33, lay, k + 15), leaf(f33, lay, k + 16), leaf(f, lay, k + 17),
    )  # fmt: skip


@kernel()
def row_capacity(flat):
    """The row table's length (ws[0]: pack's worst case of rows a step can make)."""
    return flat[9][_WS, 1]


@kernel()
def node_count(flat):
    """The forest's number of nodes (tree[1], its parents: solver.compiled.pack)."""
    return flat[9][_TREE + 1, 1]


@kernel(inline="always")  # views made in the caller (module docstring)
def unflatten(flat):
    """(m, g, tree, ptree, ws, pws, opt, iopt) as views of ``flat``'s buffers."""
    return (
        _model(flat, _M),
        _geometry(flat, _G),
        _tree(flat, _TREE),
        _ptree(flat, _PTREE),
        _ws(flat, _WS),
        _pws(flat, _PWS),
        leaf(flat[0], flat[9], _OPT),
        leaf(flat[6], flat[9], _IOPT),
    )
