"""A simulation whose state lives in arrays the compiled step updates in place.

``fast_step`` returns a new State every step, as ``solver.pipeline.step`` does, and a State
is a dozen fresh arrays: allocating them, passing them in and out of the compiled step,
building the State and its report and dropping the previous one is most of what a step
costs outside the kernel.  ``Sim`` keeps the state in its own arrays and steps them in
place (as MuJoCo's mjData), so a step only passes its input in and its report out:

    sim = Sim(model)                 # or Sim(model, state)
    for inp in inputs:
        report = sim.step(inp)       # the same StepReport as fast_step's
    state = sim.state                # a State (a copy) whenever one is wanted

``sim.advance(inp)`` is the step without its report (as mj_step on mjData): a loop then
reads what it needs, ``sim.contacts``, ``sim.report``, ``sim.state``.

On the doll's grip scene at h = 1 ms ``advance`` costs ~1.8 µs outside the kernel's own
work (packing the grip's input ~1.5; a step without input ~0.1; ``step`` ~2 µs more for
the report), against ~35 µs for fast_step (docs/performance.md).  The states are exactly
fast_step's (the same kernel, which also takes a subdivided step's parts in place:
kernel.step_parts); a step the kernel hands back (a monitor failure, an unsupported
model) runs through ``fast_step`` on a snapshot, so errors and results
are the same too.
"""

from __future__ import annotations

import numpy as np

from solver.compiled.entry import inplace_kernel
from solver.compiled.fast import (
    _NO_INPUT,
    GRIP_FORCE,
    GRIP_TORQUE,
    STATE_SET_FIELDS,
    TOUCH_FORCE,
    WRENCH,
    _input_arrays,
    entry_point,
    fast_step,
    history_arrays,
    history_fields,
    kernel_report,
)  # fmt: skip
from solver.compiled.flat import flatten
from solver.compiled.kernel import step_arrays
from solver.compiled.layout import (
    IOpt,
    Pointer,
    ReportFloat,
    ReportInt,
    SimArrays,
    StateSet,
    StepWork,
    Warm,
)
from solver.compiled.pack import FastModel
from solver.rows.grip import follow_steps, path_input
from solver.rows.pin import with_pins
from solver.solve.dispatch_kernel import OK
from solver.state import State, StepInput, StepReport, initial_state

_BOOL = ("joint_yielded", "body_asleep")
_KERNEL = entry_point(inplace_kernel)


class Sim:
    """One model's simulation, stepped in place (module docstring).  One thread at a time.

    Its arrays are views of one set of flat buffers (solver.compiled.layout.SimArrays),
    passed to the step whole: its own copy of the packed model and its workspaces, two
    sets of state arrays (``STATE_SET_FIELDS``; a step reads set ``_phase`` and writes the other,
    since it must not overwrite what it still reads and a step handed back to fast_step
    must find the old state intact), the warm keys and λ, the report."""

    def __init__(self, fm: FastModel, state: State | None = None) -> None:
        """A stepper of ``fm``'s model (solver.compiled.pack.pack) from ``state`` (rest
        when None)."""
        self.model = model = fm.model
        self._fm = fm
        rest, nb, rows = initial_state(model), len(fm.zeros), len(fm.ws.rows.body_a)
        sets = [
            StateSet(
                *(np.zeros_like(_field(rest, f, nb)) for f in STATE_SET_FIELDS),
                *(np.zeros_like(a) for a in fm.no_history),
            )
            for _ in range(3)  # the two the steps flip between, and a step's parts' spare
        ]
        self._history = bool(fm.iopt[IOpt.bdf2])
        warm = Warm(np.zeros(rows, np.int64), np.zeros(rows), np.zeros(1, np.int64))
        work = StepWork(*step_arrays(nb, len(fm.m.joint_parent), rows, len(fm.tree.parent)))
        arrays = SimArrays(fm.packed, *sets[:2], warm, np.zeros(ReportInt.SIZE, np.int64),
                           np.zeros(ReportFloat.SIZE), work, sets[2], np.zeros(rows, np.int64),
                           np.zeros(rows))  # fmt: skip
        self._flat, views = flatten(arrays)
        self._sets, self._warm = (views.set0, views.set1), views.warm
        self._rep_i, self._rep_f = views.rep_i, views.rep_f
        self.load(rest if state is None else state)

    def load(self, state: State) -> None:
        """Make ``state`` the current state (copied)."""
        nb, nj = len(self._fm.zeros), len(self._fm.m.joint_parent)
        current = (*(_field(state, f, nb) for f in STATE_SET_FIELDS),
                   *history_arrays(self._fm, state))  # fmt: skip
        if [a.shape for a in current] != [a.shape for a in self._sets[0]]:  # the step trusts these
            raise ValueError(f"Sim.load: not a state of this model ({nb} bodies, {nj} joints)")
        keys, lam, count = self._warm.keys, self._warm.lam, self._warm.n
        n = len(state.warm_key)
        if n > len(keys):  # more rows than this model can make
            raise ValueError(f"Sim.load: not a state of this model ({n} warm rows)")
        for target, value in zip(self._sets[0], current, strict=True):
            target[...] = value
        keys[:n], lam[:n], count[0] = state.warm_key, state.warm_lam, n
        self._phase = 0
        self.time, self.steps = float(state.time), int(state.step)
        self._handed_back: StepReport | None = None  # the report of a step fast_step made
        self._pins: tuple = ()  # the last step's pins (its report reads their forces)

    @property
    def state(self) -> State:
        """The current state, as a State of its own arrays."""
        n = int(self._warm.n[0])
        current = self._sets[self._phase]
        arrays = {f: a.copy() for f, a in zip(STATE_SET_FIELDS, current, strict=False)}
        if self._history:
            arrays |= {f: a.copy() if isinstance(a, np.ndarray) else a
                       for f, a in history_fields(current).items()}  # fmt: skip
        return State(
            time=self.time, step=self.steps, warm_key=self._warm.keys[:n].copy(),
            warm_lam=self._warm.lam[:n].copy(), **arrays,
        )  # fmt: skip

    def view(self) -> State:
        """The current state over this stepper's own arrays, not copied: for reading
        before the next step (which overwrites them); ``state`` is the copy to keep."""
        n = int(self._warm.n[0])
        current = self._sets[self._phase]
        arrays = dict(zip(STATE_SET_FIELDS, current, strict=False))
        if self._history:
            arrays |= history_fields(current)
        return State(
            time=self.time, step=self.steps, warm_key=self._warm.keys[:n],
            warm_lam=self._warm.lam[:n], **arrays,
        )  # fmt: skip

    def wrench(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The last step's (grip force, grip torque, touch force) (3,) each, as in its
        report, without making the report (views: read them before the next step)."""
        if self._handed_back is not None:
            r = self._handed_back
            return r.grip_force, r.grip_torque, r.touch_force
        f = self._rep_f
        return f[GRIP_FORCE], f[GRIP_TORQUE], f[TOUCH_FORCE]

    def wrench_into(self, out: np.ndarray) -> None:
        """Write the last step's (grip force, grip torque, touch force) into out (9,)."""
        if self._handed_back is None:
            out[:] = self._rep_f[WRENCH]
        else:
            out[:] = np.concatenate(self.wrench())

    def step(self, inp: StepInput | None = None) -> StepReport:
        """Advance one step of size model.options.h, exactly as ``fast_step``; its report."""
        self.advance(inp)
        return self.report

    def advance(self, inp: StepInput | None = None) -> None:
        """``step`` without making the report (~2 µs less Python), as mj_step: what a loop
        needs afterwards it reads (``report``, ``contacts``, ``state``)."""
        inp = inp or _NO_INPUT
        fm = self._fm
        self._pins = inp.pins
        ins = _input_arrays(fm, inp) if fm.reason is None else None
        if ins is not None and _KERNEL[0](self._flat, self._phase, ins) == OK:
            self._stepped()
        else:
            self._hand_back(inp)

    def follow(self, path: tuple, radius: float, coupling, wrench: np.ndarray) -> None:
        """len(wrench) steps of the pointer along ``path`` without loads: exactly the
        ``advance`` of each ``path_input(path, k, radius, coupling)``, with each step's
        (grip force, grip torque, touch force) written to wrench[k] (n, 9).  Only the
        pointer's pose changes from step to step, so its arrays are rewritten in place
        and nothing else is made: a rollout's loop without a step's Python around it."""
        fm, n = self._fm, len(wrench)
        self._pins = ()
        ins = (
            _input_arrays(fm, path_input(path, 0, radius, coupling))
            if n and fm.reason is None
            else None
        )
        if ins is None:
            return follow_steps(self, path, radius, coupling, wrench)
        kernel, flat, rep, pvec = _KERNEL[0], self._flat, self._rep_f, fm.pvec[: Pointer.radius]
        poses = np.concatenate(path, axis=1)  # each row as the kernel's pointer vector
        for k in range(n):
            pvec[:] = poses[k]
            if kernel(flat, self._phase, ins) == OK:
                self._stepped()
                wrench[k] = rep[WRENCH]
            else:
                self._hand_back(path_input(path, k, radius, coupling))
                self.wrench_into(wrench[k])

    def _stepped(self) -> None:
        """The kernel stepped in place: the other state set is now the current one."""
        self._phase ^= 1
        self.time += self.model.options.h
        self.steps += 1
        self._handed_back = None

    def _hand_back(self, inp: StepInput) -> None:
        """A step the kernel did not take in place, taken by fast_step (a
        monitor failure: its error), then loaded."""
        new, report = fast_step(self._fm, self.state, inp)
        self.load(new)
        self._handed_back = report

    @property
    def report(self) -> StepReport:
        """The last step's StepReport (a new one each time: its vectors are its own)."""
        if self._handed_back is not None:
            return self._handed_back
        report = kernel_report(self._rep_i, self._rep_f.copy())
        return with_pins(report, self._pins, self.view()) if self._pins else report

    @property
    def contacts(self) -> int:
        """The last step's contact count (StepReport.contacts), without the report."""
        if self._handed_back is not None:
            return self._handed_back.contacts
        return int(self._rep_i[ReportInt.contacts])

    @property
    def substeps(self) -> int:
        """The last step's substeps (StepReport.substeps: > 1 when it was subdivided)."""
        if self._handed_back is not None:
            return self._handed_back.substeps
        return int(self._rep_i[ReportInt.substeps])


def _field(state: State, name: str, nb: int) -> np.ndarray:
    """A field of ``state`` as the step's array (the sleep fields of a State without them:
    all awake)."""
    value = getattr(state, name)
    if name in ("body_asleep", "body_still") and len(value) == 0:
        value = np.zeros(nb)
    return np.array(value, dtype=np.bool_ if name in _BOOL else np.float64, order="C")
