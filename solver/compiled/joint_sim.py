"""The in-place stepper of a model stepped in joint space (solver.advance.joint_space).

``solver.Engine.stepper`` returns a ``JointSim`` instead of a ``Sim`` when the model
qualifies (solver.advance.joint_space.unsupported); callers cannot tell but by the
report's ``solver`` ("joint-space") and the speed.  A step's input it cannot take (pins,
a pointer touching the bones, a grip with rotation rows or force limits) hands the run
over to the maximal-coordinate ``Sim`` for good: from that step on, every step is that
stepper's (its BDF2 restarts there, as after any change of input).

The state it shows is the bodies' (pose, velocities: v = p/m), each joint's deflection
as its elastic part ``joint_q_sf`` and its spring-damper torque as ``joint_torque``.  It
keeps its BDF2 history to itself: a State taken and loaded again (here or into a Sim)
restarts BDF2 (solver.advance.bdf2_kernel.RESTART).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from solver import quat
from solver.advance import joint_space
from solver.advance.bdf2 import angular_momentum
from solver.advance.joint_space_kernel import (
    CLOCK_GRIP_FORCE,
    CLOCK_HPREV,
    GRIP_ANCHOR,
    GRIP_BODY,
    GRIP_D,
    GRIP_K,
    GRIP_RATE,
    GRIP_SIZE,
    GRIP_TARGET,
    OK,
    OPT_GRAVITY,
    OPT_MAX_SPEED,
    OPT_MAX_SPIN,
    OPT_ORIGIN,
    advance,
    offsets,
    python_views,
    refresh,
)
from solver.advance.monitor import check_state
from solver.errors import SimulationError
from solver.model import Model
from solver.rows.grip import follow_steps
from solver.state import State, StepInput, StepReport, initial_state

_ZERO3 = np.zeros(3)  # the torques a joint-space step never reports
_ZERO3.flags.writeable = False


class JointSim:
    """``model``'s simulation in joint space, stepped in place (module docstring); the
    interface of solver.compiled.sim.Sim.  ``handover(state)`` makes the stepper that takes
    over a run whose input this one cannot take."""

    def __init__(self, model: Model, state: State | None, handover: Callable[[State], object]):
        self.model = model
        self._handover, self._taken = handover, None
        tr = joint_space.tree(model)
        nb, n, nj = model.nbody, len(tr.child), model.njoint
        off = offsets(n, nb + 1, nj)
        self._fb = np.zeros(off[-1])
        self._ib = np.array([n, nb + 1, nj, *off, *tr.child, *tr.parent, *tr.joint], np.int64)
        self._tree, self._m, self._s, self._w = python_views(self._fb, self._ib)
        ap, ac, kf, df, mass, ibody, opt = self._m
        j = tr.joint
        ap[:], ac[:] = model.joint_anchor_parent[j], model.joint_anchor_child[j]
        held = model.joint_rheology[j][:, None]  # a joint without rheology rows is free
        kf[:] = np.where(held, model.joint_kf[j], 0.0)
        df[:] = np.where(held, model.joint_df[j], 0.0)
        mass[:nb], ibody[:nb] = model.body_mass, model.body_inertia
        o = model.options
        opt[OPT_GRAVITY : OPT_GRAVITY + 3] = o.gravity
        opt[OPT_MAX_SPEED], opt[OPT_MAX_SPIN] = o.max_speed, o.max_angular_speed
        first = initial_state(model) if state is None else state
        self._origin = _origin(model, tr, first)
        opt[OPT_ORIGIN : OPT_ORIGIN + 3] = self._origin
        self._grip = np.zeros(GRIP_SIZE)
        self._grip[GRIP_BODY] = -1.0
        self._h = o.h
        self._steady = joint_space.parts(o.h, joint_space.part_length(o.h), False)
        self._nb = nb
        self.load(first)

    def load(self, state: State) -> None:
        """Make ``state`` the current state (copied); the next step restarts BDF2."""
        self._taken = None
        nb, moving = self._nb, self.model.body_inv_mass > 0.0
        Q, Qp, Om, P, Pp, X, Vl, anchor, delta, torque, clock, world, _ = self._s
        if state.body_pos.shape != (nb, 3) or state.joint_anchor.shape != (self.model.njoint, 4):
            raise ValueError(f"JointSim.load: not a state of this model ({nb} bodies)")
        Q[:nb], Q[nb] = state.body_quat, quat.IDENTITY
        X[:nb], X[nb] = state.body_pos - self._origin, -self._origin
        world[:nb], world[nb] = state.body_pos, 0.0
        Om[:nb], Om[nb] = np.where(moving[:, None], state.body_omega, 0.0), 0.0
        Vl[:nb], Vl[nb] = np.where(moving[:, None], state.body_vel, 0.0), 0.0
        P[:nb, :3] = angular_momentum(self.model, Q[:nb], Om[:nb])
        P[:nb, 3:] = self.model.body_mass[:, None] * Vl[:nb]
        Qp[:], Pp[:] = Q, P
        self._w.quat_hat[:], self._w.quat_pred[:] = Q, Q  # fixed bodies' q̂ and q̃ are their pose
        anchor[:] = state.joint_anchor[self._tree.joint]
        delta[:], torque[:] = state.joint_q_sf, state.joint_torque
        clock[:] = 0.0
        self._kept = state  # the fields this stepper does not change
        self._time, self._steps = float(state.time), int(state.step)
        self._coupling, self._restart, self._parts = None, True, np.zeros((1, 2))
        self._settled, self._made, self._coasting = False, True, False
        self._loaded = False
        self._s.loads[:] = 0.0

    @property
    def state(self) -> State:
        """The current state, as a State of its own arrays."""
        if self._taken is not None:
            return self._taken.state
        return self._shown(np.copy)

    def view(self) -> State:
        """The current state over this stepper's arrays (read it before the next step)."""
        if self._taken is not None:
            return self._taken.view()
        return self._shown(lambda a: a)

    def _fresh(self) -> None:
        """Make the outputs of the last step (velocities, deflections, torques, the grip's
        force) if they are not made yet."""
        if not self._made:
            refresh(self._fb, self._ib, self._grip)
            self._made = True

    def _shown(self, own: Callable) -> State:
        self._fresh()
        nb, s, k = self._nb, self._s, self._kept
        return State(
            time=self._time, step=self._steps, body_pos=own(s.world_pos[:nb]),
            body_quat=own(s.quat[:nb]), body_vel=own(s.vel[:nb]), body_omega=own(s.omega[:nb]),
            joint_q_sf=own(s.deflection),
            joint_yielded=k.joint_yielded, joint_anchor=k.joint_anchor,
            joint_torque_avg=k.joint_torque_avg, joint_torque=own(s.torque),
        )  # fmt: skip

    def advance(self, inp: StepInput | None = None) -> None:
        """Advance one step of size model.options.h (``step`` without the report)."""
        if inp is None and self._coasting:  # the common loop: nothing to check or plan
            self._parts = self._steady
            if advance(self._fb, self._ib, self._steady, self._grip) != OK:
                self._raise_broken()
        else:
            if self._taken is None and not self._take_input(inp):
                self._taken, self._coasting = self._handover(self.state), False
            if self._taken is not None:
                self._taken.advance(inp)
                return
            self._advance_planned()
        self._made = False
        self._time += self._h
        self._steps += 1

    def _advance_planned(self) -> None:
        """A step whose parts follow from the history (a restart, or the step after one)."""
        if self._settled and not self._restart:
            self._parts = self._steady
        else:
            self._parts = joint_space.parts(self._h, self._s.clock[CLOCK_HPREV], self._restart)
            self._restart = False
            self._settled = self._parts[-1, 0] == self._steady[-1, 0]  # next: steady parts
        self._coasting = self._settled and self._coupling is None and not self._loaded
        if advance(self._fb, self._ib, self._parts, self._grip) != OK:
            self._raise_broken()

    @property
    def time(self) -> float:
        return self._time if self._taken is None else self._taken.time

    @property
    def steps(self) -> int:
        return self._steps if self._taken is None else self._taken.steps

    def _take_input(self, inp: StepInput | None) -> bool:
        """Write the step's grip and loads into the buffers; False when the input needs the
        maximal-coordinate step.  A grip or loads begun, ended or changed restart BDF2."""
        g = self._grip
        c = None if inp is None else inp.coupling
        if inp is not None and (
            inp.pins or (inp.pointer is not None and c is None and inp.pointer.radius > 0.0)
        ):  # fmt: skip
            return False
        limited = c is not None and not (c.position_only and math.isinf(c.force_limit))
        if c is not self._coupling and limited:
            return False  # rotation rows or a force limit
        self._take_loads(inp)
        if c is not self._coupling:
            self._restart |= not _same_spring(c, self._coupling)
            self._coupling = c
            g[GRIP_BODY] = -1.0 if c is None else c.body
            if c is not None:
                g[GRIP_ANCHOR : GRIP_ANCHOR + 3] = c.anchor
                g[GRIP_K], g[GRIP_D] = c.stiffness, c.damping
                self._offset = bool(c.offset.any())
        if c is not None:
            ptr = inp.pointer
            g[GRIP_TARGET : GRIP_TARGET + 3] = ptr.pos - self._origin
            g[GRIP_RATE : GRIP_RATE + 3] = ptr.vel
            if self._offset:  # the grip point is off the pointer's centre
                lever = quat.rotate(ptr.quat, c.offset)
                g[GRIP_TARGET : GRIP_TARGET + 3] += lever
                g[GRIP_RATE : GRIP_RATE + 3] += quat.cross(ptr.omega, lever)
        return True

    def _take_loads(self, inp: StepInput | None) -> None:
        """The step's loads (torque about each body's centre, force at it) into the
        buffer; restarts BDF2 when they differ from the last step's."""
        nb, loads = self._nb, self._s.loads
        force = None if inp is None else inp.body_force
        torque = None if inp is None else inp.body_torque
        if force is None and torque is None:
            if self._loaded:
                loads[:] = 0.0
                self._loaded, self._restart = False, True
            return
        new = np.zeros((nb, 6))
        if torque is not None:
            new[:, :3] = torque
        if force is not None:
            new[:, 3:] = force
        if not (self._loaded and np.array_equal(new, loads[:nb])):
            loads[:nb] = new
            self._loaded, self._restart = True, True

    def _raise_broken(self) -> None:
        self._fresh()
        nb, s = self._nb, self._s
        vel = np.hstack([s.vel[:nb], s.omega[:nb]])
        check_state(self.model, self._steps, self._time, s.world_pos[:nb], s.quat[:nb], vel)
        raise SimulationError("state became non-finite (NaN or infinity)", self._steps,
                              self._time, None)  # fmt: skip

    def step(self, inp: StepInput | None = None) -> StepReport:
        """Advance one step; its report."""
        self.advance(inp)
        return self.report

    @property
    def report(self) -> StepReport:
        """The last step's StepReport: no rows, contacts or iterations; the grip's force."""
        if self._taken is not None:
            return self._taken.report
        self._fresh()
        force = self._s.clock[CLOCK_GRIP_FORCE : CLOCK_GRIP_FORCE + 3].copy()
        return StepReport(rows=0, contacts=0, iterations=0, residual=0.0, solver="joint-space",
                          grip_force=force, substeps=len(self._parts))  # fmt: skip

    def wrench(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The last step's (grip force, grip torque, touch force) (3,) each."""
        if self._taken is not None:
            return self._taken.wrench()
        self._fresh()
        return self._s.clock[CLOCK_GRIP_FORCE : CLOCK_GRIP_FORCE + 3], _ZERO3, _ZERO3

    def wrench_into(self, out: np.ndarray) -> None:
        """Write the last step's (grip force, grip torque, touch force) into out (9,)."""
        out[:] = np.concatenate(self.wrench())

    def follow(self, path: tuple, radius: float, coupling, wrench: np.ndarray) -> None:
        """Steps along a pointer path (solver.compiled.sim.Sim.follow), one by one."""
        follow_steps(self, path, radius, coupling, wrench)

    @property
    def contacts(self) -> int:
        return 0 if self._taken is None else self._taken.contacts

    @property
    def substeps(self) -> int:
        """The last step's parts (a restart is three or more)."""
        return len(self._parts) if self._taken is None else self._taken.substeps


def _same_spring(a, b) -> bool:
    """Two couplings (or None) pull the same point of the same body with the same gains."""
    if a is None or b is None:
        return a is b
    return (a.body == b.body and a.stiffness == b.stiffness and a.damping == b.damping
            and np.array_equal(a.anchor, b.anchor))  # fmt: skip


def _origin(model: Model, tree: joint_space.JointTree, state: State) -> np.ndarray:
    """The step's origin: the world position of the tree's first joint's anchor on its
    fixed parent (every body's spatial quantities are taken about it)."""
    p, anchor = int(model.joint_parent[tree.joint[0]]), model.joint_anchor_parent[tree.joint[0]]
    if p < 0:
        return anchor.copy()
    return state.body_pos[p] + quat.rotate(state.body_quat[p], anchor)


def compile_kernels() -> None:
    """Compile (or load from numba's cache) every kernel a JointSim calls, on buffers of a
    one-joint tree with nothing in it (the results are discarded): a build of the compiled
    step covers them whichever model it is made with (puppetcli.run.build)."""
    off = offsets(1, 2, 1)
    fb = np.zeros(off[-1])
    ib = np.array([1, 2, 1, *off, 0, 1, 0], np.int64)
    python_views(fb, ib)
    grip = np.zeros(GRIP_SIZE)
    grip[GRIP_BODY] = -1.0
    with np.errstate(all="ignore"):  # a massless body: its outputs are NaN, and unused
        advance(fb, ib, np.zeros((0, 2)), grip)
        refresh(fb, ib, grip)
