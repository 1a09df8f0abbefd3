"""A simulation whose state lives in arrays the compiled step updates in place.

``fast_step`` returns a new State every step, as ``solver.step.step`` does, and a State
is a dozen fresh arrays: boxing them out of the compiled step, building the State and
dropping the previous one costs tens of microseconds per step, about a third of a doll
step.  ``Sim`` keeps the state in its own arrays and steps them in place (as MuJoCo's
mjData), so a step only passes its input in and its report out:

    sim = Sim(model)                 # or Sim(model, state)
    for inp in inputs:
        report = sim.step(inp)       # the same StepReport as fast_step's
    state = sim.state                # a State (a copy) whenever one is wanted

The states are exactly fast_step's (the same kernel); a step the kernel hands back
(substeps, a box–box contact, a monitor failure, an unsupported model) runs through
``fast_step`` on a snapshot, so errors and results are the same too.
"""

from __future__ import annotations

import numpy as np

from solver.fast import _input_arrays, fast_step, kernel_report
from solver.fast.kernel import OK, inplace_kernel
from solver.fast.pack import fast_model
from solver.model import Model
from solver.state import State, StepInput, StepReport, initial_state

_FIELDS = (
    "body_pos", "body_quat", "body_vel", "body_omega", "joint_q_sf", "joint_yielded",
    "joint_anchor", "joint_torque_avg", "joint_torque",
)  # fmt: skip


class Sim:
    """One model's simulation, stepped in place (module docstring).  One thread at a time."""

    def __init__(self, model: Model, state: State | None = None) -> None:
        self.model = model
        self._fm = fast_model(model)
        self._rep_i, self._rep_f = np.zeros(4, np.int64), np.zeros(10)
        self.load(initial_state(model) if state is None else state)

    def load(self, state: State) -> None:
        """Make ``state`` the current state (copied)."""
        dtypes = [np.bool_ if f == "joint_yielded" else np.float64 for f in _FIELDS]
        self._buf = tuple(
            np.array(getattr(state, f), dtype=d, order="C")
            for f, d in zip(_FIELDS, dtypes, strict=True)
        )
        room = max(len(self._fm.ws[0][0]), len(state.warm_key))
        keys, lam = np.zeros(room, np.int64), np.zeros(room)
        keys[: len(state.warm_key)], lam[: len(state.warm_lam)] = state.warm_key, state.warm_lam
        self._warm = (keys, lam, np.array([len(state.warm_key)], np.int64))
        self.time, self.steps = float(state.time), int(state.step)

    @property
    def state(self) -> State:
        """The current state, as a State of its own arrays."""
        n = int(self._warm[2][0])
        arrays = {f: a.copy() for f, a in zip(_FIELDS, self._buf, strict=True)}
        return State(
            time=self.time, step=self.steps, warm_key=self._warm[0][:n].copy(),
            warm_lam=self._warm[1][:n].copy(), **arrays,
        )  # fmt: skip

    def step(self, inp: StepInput | None = None) -> StepReport:
        """Advance one step of size model.options.h, exactly as ``fast_step``."""
        inp = inp or StepInput()
        fm = self._fm
        ins = _input_arrays(fm, inp) if fm.reason is None else None
        if ins is not None:
            status, _ = inplace_kernel(
                fm.m, fm.g, fm.tree, fm.ptree, fm.ws, fm.pws, fm.opt, fm.iopt, self._buf,
                self._warm, ins, self._rep_i, self._rep_f,
            )  # fmt: skip
            if status == OK:
                self.time += self.model.options.h
                self.steps += 1
                return kernel_report(self._rep_i, self._rep_f)
        new, report = fast_step(self.model, self.state, inp)
        self.load(new)
        return report
