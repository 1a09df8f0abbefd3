"""The compiled step's entry points: what Python calls, and all it passes and gets back.

Both take the packed model as its flat buffers (``solver.compiled.flat``: ten arrays instead
of ~100, rebuilt as views in compiled code) and write the new state into arrays the
caller made:

- ``fast_kernel`` (``fast_step``): out are fresh arrays that become the new State; the
  warm keys and λ, whose length is known only at the end, are returned.
- ``inplace_kernel`` (``solver.compiled.sim.Sim``): all of the Sim's arrays are views of one
  set of flat buffers, its own copy of the model's with the state after it (two sets of
  state arrays: it reads one, writes the other, and the Sim flips between them; the
  warm keys and λ, the report, the step's scratch arrays), so a step unboxes 15 arrays
  (with the input's five), boxes none and allocates nothing but the substep test's and
  sleeping's few arrays (the solvers work in the step's scratch arrays).

State tuples: prev, out (x, q, v, ω, q_sf, yielded, anchor, τ_avg, τ, asleep, still) with
the warm keys and λ beside them; prev is read (except τ), out written.  They must not
share memory (the step reads prev while it writes out, and prev must stay intact for a
step it hands back).
"""

from __future__ import annotations

from solver.compiled.flat import NLEAF, SCHEMA, leaf
from solver.compiled.kernel import _step, step_kernel
from solver.jit import kernel
from solver.solve.dispatch_kernel import OK


@kernel(error_model="numpy")
def fast_kernel(flat, prev, keys, lam, inp, out, rep_i, rep_f):
    """One step from prev (x … τ: a previous out, τ unread) and its warm keys and λ into
    out (module docstring); rep_i (4,) (rows, contacts, iterations, solver) and rep_f
    (10,) (residual, grip f, grip τ, touch f) receive the report.  Returns (status, warm
    keys (n,), warm λ (n,)); on SUBSTEP rep_i[0] is the number of substeps asked for, on
    any status but OK out holds nothing."""
    st = _with_warm(prev, keys, lam)
    status, _, new_keys, new_lam, _, _ = step_kernel(flat, st, inp, out, rep_i, rep_f)
    return status, new_keys, new_lam


@kernel(error_model="numpy", inline="always")
def _with_warm(prev, keys, lam):
    """The step's st: prev's (x, q, v, ω, q_sf, yielded, anchor, τ_avg) and (asleep, still)
    with the warm keys and λ between them (τ, prev[8], is not read)."""
    return (prev[0], prev[1], prev[2], prev[3], prev[4], prev[5], prev[6], prev[7], keys, lam,
            prev[9], prev[10])  # fmt: skip


_SET = ("f3", "f4", "f3", "f3", "f3", "b", "f4", "f", "f3", "b", "f")  # x … τ, asleep, still
NSET = len(_SET)
_SOLVERS = (("b",) * 3, ("i",) * 7, ("f",) * 7, ("f6", "f6"), "f")
_SCRATCH = (("f6", "b", "b", ("b", "f"), "f", "f", "f6", ("f3", "f3", "b"), "f3", ("f3", "f3"),
             "b", _SOLVERS), "i", "f")  # fmt: skip
SIM_SCHEMA = (*SCHEMA, _SET, _SET, ("i", "f", "i"), "i", "f", _SCRATCH)
"""A Sim's arrays (flat.flatten): its own copy of the packed model (SCHEMA: its
workspaces are the Sim's alone), two state sets, warm (keys, λ, count (1,)) with room for
every row, rep_i (4,), rep_f (10,), the step's arrays (kernel.step_arrays).  One
set of buffers holds them all, so a step unboxes ten arrays for all of them and
allocates none."""


@kernel(inline="always")  # views made in the caller (solver.compiled.flat)
def _scratch(flat, k):
    """The scratch arrays whose first leaf is k of a Sim's flat buffers: (the step's
    scratch tuple, warm keys, warm λ)."""
    f, f3, f6, i, b, lay = flat[0], flat[1], flat[3], flat[6], flat[8], flat[9]
    scratch = (
        leaf(f6, lay, k), leaf(b, lay, k + 1), leaf(b, lay, k + 2),
        (leaf(b, lay, k + 3), leaf(f, lay, k + 4)), leaf(f, lay, k + 5), leaf(f, lay, k + 6),
        leaf(f6, lay, k + 7), (leaf(f3, lay, k + 8), leaf(f3, lay, k + 9), leaf(b, lay, k + 10)),
        leaf(f3, lay, k + 11), (leaf(f3, lay, k + 12), leaf(f3, lay, k + 13)),
        leaf(b, lay, k + 14), _solvers(flat, k + 15),
    )  # fmt: skip
    return scratch, leaf(i, lay, k + 35), leaf(f, lay, k + 36)


@kernel(inline="always")  # views made in the caller (solver.compiled.flat)
def _solvers(flat, k):
    """The solvers' scratch arrays (kernel.step_arrays) whose first leaf is k."""
    f, f6, i, b, lay = flat[0], flat[3], flat[6], flat[8], flat[9]
    return (
        (leaf(b, lay, k), leaf(b, lay, k + 1), leaf(b, lay, k + 2)),
        (leaf(i, lay, k + 3), leaf(i, lay, k + 4), leaf(i, lay, k + 5), leaf(i, lay, k + 6),
         leaf(i, lay, k + 7), leaf(i, lay, k + 8), leaf(i, lay, k + 9)),
        (leaf(f, lay, k + 10), leaf(f, lay, k + 11), leaf(f, lay, k + 12), leaf(f, lay, k + 13),
         leaf(f, lay, k + 14), leaf(f, lay, k + 15), leaf(f, lay, k + 16)),
        (leaf(f6, lay, k + 17), leaf(f6, lay, k + 18)),
        leaf(f, lay, k + 19),
    )  # fmt: skip


@kernel(inline="always")  # views made in the caller (solver.compiled.flat)
def _state_set(flat, k):
    """The state set whose first leaf is k of a Sim's flat buffers."""
    f, f3, f4, b, lay = flat[0], flat[1], flat[2], flat[8], flat[9]
    return (
        leaf(f3, lay, k), leaf(f4, lay, k + 1), leaf(f3, lay, k + 2), leaf(f3, lay, k + 3),
        leaf(f3, lay, k + 4), leaf(b, lay, k + 5), leaf(f4, lay, k + 6), leaf(f, lay, k + 7),
        leaf(f3, lay, k + 8), leaf(b, lay, k + 9), leaf(f, lay, k + 10),
    )  # fmt: skip


@kernel(error_model="numpy", _nrt=False)
def inplace_kernel(flat, phase, inp):
    """``fast_kernel`` on a Sim's arrays, the flat buffers of SIM_SCHEMA (the model's
    leaves first, so they are also the model's flat): reads state set ``phase`` (0 or
    1), writes the other (the Sim then flips phase), replaces the warm keys and λ, fills
    rep_i and rep_f.  Returns (status, substeps asked for); on a status other than OK
    ``phase`` and the warm keys are as they were.  It runs kernel._step on the Sim's
    scratch arrays: outside the substep test and sleeping a Sim's step allocates nothing
    and counts no references (compiled without: ``_nrt=False``, which also unboxes its
    arguments without making numba's wrappers for them)."""
    f, i, lay = flat[0], flat[6], flat[9]
    prev = _state_set(flat, NLEAF + NSET * phase)
    out = _state_set(flat, NLEAF + NSET - NSET * phase)
    w = NLEAF + 2 * NSET
    keys, lam, count = leaf(i, lay, w), leaf(f, lay, w + 1), leaf(i, lay, w + 2)
    rep_i, rep_f = leaf(i, lay, w + 3), leaf(f, lay, w + 4)
    scratch, new_keys, new_lam = _scratch(flat, w + 5)
    nw = count[0]
    st = _with_warm(prev, keys[:nw], lam[:nw])
    status, n = _step(flat, st, inp, out, rep_i, rep_f, scratch, new_keys, new_lam)
    if status != OK:
        return status, rep_i[0]
    for r in range(n):
        keys[r], lam[r] = new_keys[r], new_lam[r]
    count[0] = n
    return OK, 0
