"""A FastModel's static arrays stored in a few buffers, rebuilt as views in compiled code.

The compiled step takes a structure of about a hundred arrays (``solver.compiled.layout``'s
Packed: model, geometry, forest, workspaces, options).  Passing them from Python costs numba
~0.1 µs of unboxing per array on every call (~13 µs a step); a view made inside compiled
code costs a few ns and no Python object.  So ``flatten`` copies every leaf into one buffer
per kind of leaf and hands back the same structure of views (what Python code reads and
writes: ``fm.packed.ws.cycles``, ``fm.iopt[IOpt.profiling] = 1``), and the generated
``solver.compiled.views`` rebuild the structures from the buffers in compiled code, sharing
their memory.

    flat = (f (·,), f3 (·,3), f4 (·,4), f6 (·,6), f33 (·,3,3), f66 (·,6,6) float64,
            i (·,), i6 (·,6) int64, b (·,) bool, layout (nleaf, 2) int64)

A leaf is a run of rows of the buffer of its kind (its dtype and trailing shape), so its
view needs no reshape (~70 ns each in numba).  layout holds each leaf's (offset, rows), in
depth-first order of the structure's fields.  The compiled views are ``numba.carray``s
over the buffer's memory that hold no reference to it: a slice would, and its reference
counting across the rebuild's calls costs ~45 ns a view (5 µs a step); without it a view
costs a few ns.
So the caller keeps the buffers alive for the call (Python holds ``fm.flat``), and no
compiled function may return one of these views to Python.  The views' functions are
inlined into their caller (``inline="always"``): made in a function of their own, the
hundred views were returned as one tuple, a few kilobytes of array structs copied out of
it on every step (the one-joint creep step at 1 ms: 7.0 → 3.5 µs a kernel call).  An
array that appears twice (ptree's arrays are tree's) is stored once and both rows point
at it.  The views are generated from the layout (numba can neither loop over a
heterogeneous tuple nor cache code made at run time); ``flatten`` checks the arrays it is
given against the layout's kinds, so the two cannot drift apart silently.
"""

from __future__ import annotations

import numpy as np
from llvmlite import ir
from numba import carray, types
from numba.core import cgutils
from numba.extending import intrinsic
from numba.np.arrayobj import make_array

from solver.compiled.layout import BUFFERS, Packed, leaf_of
from solver.jit import kernel

_ROWS = leaf_of(Packed, "ws.rows.body_a")
_NODES = leaf_of(Packed, "tree.parent")

ALIGN = 8  # rows: every leaf starts on a 64-byte boundary of its buffer


def _leaves(x, kind, path: str = "") -> list:
    """[(array, buffer kind)] of x in depth-first order, checked against ``kind`` (a
    buffer kind or a structure of solver.compiled.layout)."""
    if isinstance(kind, str):
        dtype, trail = BUFFERS[kind]
        ok = isinstance(x, np.ndarray) and x.dtype == dtype and x.ndim == 1 + len(trail)
        if not (ok and x.shape[1:] == trail and x.flags.c_contiguous):
            got = f"{x.dtype} {x.shape}" if isinstance(x, np.ndarray) else type(x).__name__
            raise TypeError(f"packed array {path or '.'}: expected {kind}, got {got}")
        return [(x, kind)]
    if not isinstance(x, kind):
        raise TypeError(f"packed {path or '.'}: expected {kind.__name__}, got {type(x).__name__}")
    pairs = zip(x._fields, x, kind.KINDS, strict=True)
    return [leaf for name, y, k in pairs for leaf in _leaves(y, k, f"{path}.{name}")]


def _replace(x, views: dict):
    return type(x)(*(_replace(y, views) for y in x)) if isinstance(x, tuple) else views[id(x)]


def flatten(parts: tuple) -> tuple[tuple, tuple]:
    """(flat, views): ``parts`` (a structure of solver.compiled.layout) copied into the
    buffers of ``flat`` (module docstring), and the same structure of views into them."""
    leaves = _leaves(parts, type(parts))
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
def row_pointer(typingctx, buf, row):
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
    return carray(row_pointer(buf, lay[k, 0]), (lay[k, 1],) + buf.shape[1:])


@kernel(_nrt=True)  # returns a view: never without NRT (kernel._step)
def square(buf, n):
    """The first n² entries of buf (1-D, C-contiguous) as an (n, n) array that holds no
    reference to buf (module docstring: the caller keeps buf alive)."""
    return carray(row_pointer(buf, 0), (n, n))


@kernel()
def row_capacity(flat):
    """The row table's length (pack's worst case of rows a step can make)."""
    return flat[9][_ROWS, 1]


@kernel()
def node_count(flat):
    """The forest's number of nodes (its parents' length: solver.compiled.pack)."""
    return flat[9][_NODES, 1]
