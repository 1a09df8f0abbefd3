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

State sets (layout.StateSet): prev, out with the warm keys and λ beside them; prev is read
(except τ), out written.  They must not
share memory (the step reads prev while it writes out, and prev must stay intact for a
step it hands back).
"""

from __future__ import annotations

from solver.compiled.kernel import _step, step_kernel, step_parts, step_state
from solver.compiled.layout import SimArrays, StateSet, leaf_count, leaf_of
from solver.compiled.views import leaf_f, leaf_i, state_set_view, step_work_view, warm_view
from solver.jit import kernel
from solver.solve.dispatch_kernel import OK, RESTART, SUBSTEP

_SET0 = leaf_of(SimArrays, "set0")
_NSET = leaf_count(StateSet)
_WARM, _WORK = leaf_of(SimArrays, "warm"), leaf_of(SimArrays, "work")
_REP_I, _REP_F = leaf_of(SimArrays, "rep_i"), leaf_of(SimArrays, "rep_f")
_SPARE = leaf_of(SimArrays, "spare")
_SPARE_KEYS, _SPARE_LAM = leaf_of(SimArrays, "spare_keys"), leaf_of(SimArrays, "spare_lam")


@kernel(error_model="numpy")
def fast_kernel(flat, prev, keys, lam, inp, out, rep_i, rep_f):
    """One step from prev (a previous out, τ unread) and its warm keys and λ into out
    (module docstring); rep_i and rep_f (layout.ReportInt, ReportFloat) receive the
    report.  Returns (status, warm keys (n,), warm λ (n,)); a step the joints' tension
    subdivides, or a BDF2 restart, is taken in its parts (kernel.step_parts); on any
    status but OK out holds nothing."""
    st = step_state(prev, keys, lam)
    status, _, new_keys, new_lam, _, _ = step_kernel(flat, st, inp, out, rep_i, rep_f)
    return status, new_keys, new_lam


@kernel(error_model="numpy", _nrt=False)
def inplace_kernel(flat, phase, inp):
    """``fast_kernel`` on a Sim's arrays, the flat buffers of layout.SimArrays (the model's
    leaves first, so they are also the model's flat): reads state set ``phase`` (0 or
    1), writes the other (the Sim then flips phase), replaces the warm keys and λ, fills
    rep_i and rep_f.  Returns the status; on a status other than OK ``phase`` and the
    warm keys are as they were (a step in parts, kernel.step_parts, writes the other set
    and the spare one in turn, never the one it reads).  It runs kernel._step on the Sim's
    scratch arrays: outside the substep test and sleeping a Sim's step allocates nothing
    and counts no references (compiled without: ``_nrt=False``, which also unboxes its
    arguments without making numba's wrappers for them)."""
    prev = state_set_view(flat, _SET0 + _NSET * phase)
    out = state_set_view(flat, _SET0 + _NSET - _NSET * phase)
    warm = warm_view(flat, _WARM)
    rep_i, rep_f = leaf_i(flat, _REP_I), leaf_f(flat, _REP_F)
    work = step_work_view(flat, _WORK)
    nw = warm.n[0]
    st = step_state(prev, warm.keys[:nw], warm.lam[:nw])
    status, n = _step(flat, st, inp, out, rep_i, rep_f, work.scratch, work.keys, work.lam, 0)
    if status in (SUBSTEP, RESTART):
        spare = state_set_view(flat, _SPARE)
        spare_keys, spare_lam = leaf_i(flat, _SPARE_KEYS), leaf_f(flat, _SPARE_LAM)
        status, n = step_parts(flat, st, inp, (out, spare), rep_i, rep_f, work.scratch,
                               (work.keys, work.lam, spare_keys, spare_lam), status)  # fmt: skip
    if status != OK:
        return status
    for r in range(n):
        warm.keys[r], warm.lam[r] = work.keys[r], work.lam[r]
    warm.n[0] = n
    return OK
