"""The solver's one entry: a model made ready to step, and its steppers.

    import solver
    engine = solver.Engine(model)              # once per model (and per thread)
    state, report = engine.step(state, inp)    # a new State each step; solver.step(engine, …)
    stepper = engine.stepper(state)            # in place, for long runs:
    report = stepper.step(inp)                 #   or stepper.advance(inp), without the report
    state = stepper.state                      #   a State (a copy) whenever one is wanted

``model.options.engine`` picks the implementation: ``"compiled"`` (the default: the numba
step of ``solver.compiled``, which hands any step it does not do itself to the numpy
step) or ``"numpy"`` (``solver.pipeline``, the readable specification of the step).  They
give the same states to rounding (tests/solver/test_fast.py), with one exception: the
compiled engine's in-place stepper takes a ``bdf2`` tree of spring-damper joints in joint
space (solver.advance.joint_space, whose numpy specification is tested against it), a
different discretisation of the same equations, while the numpy engine steps it with rows.
An Engine is the explicit per-model context of a run: for the compiled step it holds the
packed arrays and workspaces (``solver.compiled.pack``) and those of the substep models it
meets, so one engine serves one thread at a time.
"""

from __future__ import annotations

import numpy as np

from solver import pipeline
from solver.advance import joint_space
from solver.model import Model
from solver.rows.grip import follow_steps
from solver.state import State, StepInput, StepReport, initial_state

ENGINES = ("compiled", "numpy")


class Engine:
    """``model`` ready to step with the implementation ``model.options.engine`` names."""

    def __init__(self, model: Model) -> None:
        if model.options.engine not in ENGINES:
            raise ValueError(
                f"Options.engine: expected one of {', '.join(ENGINES)}, "
                f"got {model.options.engine!r}"
            )
        self.model = model
        self.packed = None
        self.joint_space = False
        if model.options.engine == "compiled":
            from solver.compiled.fast import fast_step  # numba loads only for the compiled step
            from solver.compiled.pack import pack

            self.packed = pack(model)
            self._fast_step = fast_step  # (an import in ``step`` would cost ~1 µs a step)
            self.joint_space = joint_space.unsupported(model) is None

    @property
    def compiled(self) -> bool:
        """True when steps run on the compiled step (they may still hand a step back)."""
        return self.packed is not None

    def step(self, state: State, inp: StepInput | None = None) -> tuple[State, StepReport]:
        """One step of size model.options.h from ``state``: (new State, its report)."""
        if self.packed is None:
            return pipeline.step(self.model, state, inp)
        return self._fast_step(self.packed, state, inp)

    def stepper(self, state: State | None = None):
        """An in-place stepper from ``state`` (the rest state when None): a
        solver.compiled.joint_sim.JointSim when ``joint_space`` (the model is one tree of
        spring-damper joints stepped with bdf2: solver.advance.joint_space), else a
        solver.compiled.sim.Sim."""
        if self.packed is None:
            return NumpyStepper(self.model, state)
        from solver.compiled.sim import Sim

        if self.joint_space:
            from solver.compiled.joint_sim import JointSim

            return JointSim(self.model, state, lambda s: Sim(self.packed, s))
        return Sim(self.packed, state)


def step(engine: Engine, state: State, inp: StepInput | None = None) -> tuple[State, StepReport]:
    """``engine.step(state, inp)``: one step; make the Engine once per model."""
    return engine.step(state, inp)


class NumpyStepper:
    """The numpy step with the in-place stepper's interface (``solver.compiled.sim.Sim``):
    the state is replaced, not updated in place, but callers cannot tell."""

    def __init__(self, model: Model, state: State | None = None) -> None:
        self.model = model
        self.load(initial_state(model) if state is None else state)

    def load(self, state: State) -> None:
        """Make ``state`` the current state."""
        self._state = state
        self._report: StepReport | None = None

    @property
    def state(self) -> State:
        """The current state (States are never changed: no copy is needed)."""
        return self._state

    def view(self) -> State:
        """The current state (as ``state``: a State is never changed)."""
        return self._state

    def wrench(self) -> tuple:
        """The last step's (grip force, grip torque, touch force), as in its report."""
        r = self._report
        return r.grip_force, r.grip_torque, r.touch_force

    def follow(self, path: tuple, radius: float, coupling, wrench: np.ndarray) -> None:
        """Steps along a pointer path (solver.compiled.sim.Sim.follow), one by one."""
        follow_steps(self, path, radius, coupling, wrench)

    def wrench_into(self, out) -> None:
        """Write the last step's (grip force, grip torque, touch force) into out (9,)."""
        out[:] = np.concatenate(self.wrench())

    @property
    def time(self) -> float:
        return self._state.time

    @property
    def steps(self) -> int:
        return self._state.step

    def step(self, inp: StepInput | None = None) -> StepReport:
        """Advance one step; its report."""
        self.advance(inp)
        return self._report

    def advance(self, inp: StepInput | None = None) -> None:
        """Advance one step (the report stays readable as ``report``)."""
        self._state, self._report = pipeline.step(self.model, self._state, inp)

    @property
    def report(self) -> StepReport:
        return self._report

    @property
    def contacts(self) -> int:
        return self._report.contacts

    @property
    def substeps(self) -> int:
        return self._report.substeps
