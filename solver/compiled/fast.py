"""The compiled step: ``fast_step`` is ``solver.pipeline.step`` in one numba call.

    fm = solver.compiled.pack.pack(model)      # solver.engine.Engine does this
    state, report = fast_step(fm, state, inp)

Same pipeline, rows, row order, warm start by row key, solvers (direct by an exact
linear-time elimination over the joint tree, PGS by ``solver.solve.pgs``'s kernel), the same
State and StepReport, and the same errors: whenever the compiled step meets something
it does not do itself — a step the monitor rejects (non-finite, energy blow-up, joint
torn apart), a degenerate direct system, inputs of unexpected shapes — it hands that step
to ``solver.pipeline.step``, which then raises the usual SimulationError (step, time,
bone) or computes the step.  Results agree with the numpy step to rounding (the tests compare them).

Not compiled (``supports`` is False, ``fast_step`` simply runs the numpy step):
method "reference".

The first call in a fresh checkout compiles the kernels (numba, cached on disk beside
each kernel's source: solver.jit); later processes load them from the cache.  A FastModel
holds workspaces: one model, one thread at a time.
"""

from __future__ import annotations

import dataclasses
from dataclasses import replace

import numpy as np

from solver.compiled.entry import fast_kernel
from solver.compiled.layout import (
    Coupling,
    Input,
    IOpt,
    PinVec,
    Pointer,
    ReportFloat,
    StateSet,
)
from solver.compiled.pack import NO_FLAGS, FastModel
from solver.pipeline import step
from solver.rows.grip import coupling_vector
from solver.rows.grip_kernel import MODE_GRIP, MODE_NONE, MODE_TOUCH
from solver.rows.pin import with_pins
from solver.state import NO_PINS, NO_SLIP, State, StepInput, StepReport

__all__ = ["fast_step", "supports"]

SOLVER_NAMES = ("direct", "pgs", "hybrid")
_F8, _I8, _B1 = np.dtype(np.float64), np.dtype(np.int64), np.dtype(np.bool_)
_NO_VEC = np.zeros(Coupling.SIZE)  # the pointer / coupling argument when there is none (never read)
_NO_INPUT = StepInput()  # frozen: one for every step without input
_NO_PINS = (np.zeros((0, PinVec.SIZE)), np.zeros(0, np.int64))  # the pins of a step without
# The report's and the pointer's offsets as plain ints and slices: an enum member costs an
# attribute lookup each time it is read, and these are read every step.
_RESIDUAL, _RADIUS = int(ReportFloat.residual), int(Pointer.radius)
GRIP_FORCE = slice(int(ReportFloat.grip_force), int(ReportFloat.grip_torque))
GRIP_TORQUE = slice(int(ReportFloat.grip_torque), int(ReportFloat.touch_force))
TOUCH_FORCE = slice(int(ReportFloat.touch_force), int(ReportFloat.SIZE))
WRENCH = slice(int(ReportFloat.grip_force), int(ReportFloat.SIZE))
"""rep_f's grip force, grip torque, touch force, and the three together."""
_new_tuple = tuple.__new__  # a named tuple made so skips its Python __new__ (~0.4 µs a step)


def supports(fm: FastModel) -> bool:
    """True when ``fast_step`` compiles the steps of ``fm``'s model (any StepInput is
    accepted)."""
    return fm.reason is None


def _arr(x, dtype: np.dtype, shape: tuple) -> np.ndarray | None:
    """x as a C-contiguous writable array of dtype and shape (so the kernel's argument
    types never change), or None if it has another shape (the numpy step then decides
    what it means)."""
    if not (
        type(x) is np.ndarray and x.dtype == dtype and x.flags.c_contiguous and x.flags.writeable
    ):
        x = np.array(x, dtype=dtype, order="C")
    return x if x.shape == shape else None


def _state_arrays(fm: FastModel, state: State) -> tuple | None:
    """The kernel's (x … τ, warm keys, warm λ); the arrays of the State fast_step returned
    last are trusted as they are."""
    if state is fm.last[0]:
        return fm.last[1]
    nb, nj = len(fm.m.body_mass), len(fm.m.joint_parent)
    arrays = (
        _arr(state.body_pos, _F8, (nb, 3)),
        _arr(state.body_quat, _F8, (nb, 4)),
        _arr(state.body_vel, _F8, (nb, 3)),
        _arr(state.body_omega, _F8, (nb, 3)),
        _arr(state.joint_q_sf, _F8, (nj, 3)),
        _arr(state.joint_yielded, _B1, (nj,)),
        _arr(state.joint_anchor, _F8, (nj, 4)),
        _arr(state.joint_torque_avg, _F8, (nj,)),
    )
    awake = len(state.body_asleep) == 0  # a State made without the sleep fields
    sleep = (
        _arr(np.zeros(nb, bool) if awake else state.body_asleep, _B1, (nb,)),
        _arr(np.zeros(nb) if awake else state.body_still, _F8, (nb,)),
    )
    nw = np.shape(state.warm_key)[:1]
    warm = (_arr(state.warm_key, _I8, nw), _arr(state.warm_lam, _F8, nw))
    if any(a is None for a in (*arrays, *sleep, *warm)):
        return None
    # τ is not read: q_sf, of its type, stands in
    prev = _new_tuple(StateSet, (*arrays, arrays[4], *sleep, *history_arrays(fm, state)))
    return prev, *warm


def history_arrays(fm: FastModel, state: State) -> tuple:
    """The kernel's StateSet history (prev_x … prev_q_sf, hist (prev_h, prev_mark, prev_load)) of
    ``state``: fm's zeros (read as "no history") when it has none or is not of this
    model."""
    nb, nj = len(fm.m.body_mass), len(fm.m.joint_parent)
    if state.prev_h > 0.0:
        shapes = ((nb, 3), (nb, 4), (nb, 3), (nb, 3), (nj, 3))
        values = (state.prev_pos, state.prev_quat, state.prev_vel, state.prev_omega,
                  state.prev_q_sf)  # fmt: skip
        arrays = tuple(_arr(v, _F8, shape) for v, shape in zip(values, shapes, strict=True))
        if all(a is not None for a in arrays):
            return (*arrays, np.array([state.prev_h, state.prev_mark, state.prev_load]))
    return fm.no_history


def _input_arrays(fm: FastModel, inp: StepInput) -> tuple | None:
    """The kernel's input (layout.Input: force, torque, pointer, coupling, flags), or None
    when the numpy step must decide what the input means.  The pointer and the flags are
    fm's own arrays, rewritten for every step (they are read only during it).  A step
    without input gets one tuple of arrays of its own, made once (~0.5 µs a step)."""
    if inp is _NO_INPUT:
        if fm.no_input is None:
            flags = np.array(NO_FLAGS, _I8)  # never rewritten, unlike fm.ivec
            fm.no_input = _new_tuple(Input, (fm.zeros, fm.zeros, _NO_VEC, _NO_VEC, flags,
                                             *_NO_PINS))  # fmt: skip
        return fm.no_input
    nb = len(fm.zeros)
    force, torque, ptr, cpl = inp.body_force, inp.body_torque, inp.pointer, inp.coupling
    loads = (force is not None, torque is not None)
    force = fm.zeros if force is None else _arr(force, _F8, (nb, 3))
    torque = fm.zeros if torque is None else _arr(torque, _F8, (nb, 3))
    if force is None or torque is None:
        return None
    pvec = cvec = _NO_VEC
    mode, body, position_only = MODE_NONE, 0, False
    if ptr is not None and (cpl is not None or ptr.radius > 0.0):
        pvec, (pos, rotation, vel, omega) = fm.pvec, fm.pointer
        try:
            if not len(ptr.pos) == len(ptr.vel) == len(ptr.omega) == 3 == len(ptr.quat) - 1:
                return None
            pos[...], rotation[...], vel[...], omega[...] = ptr.pos, ptr.quat, ptr.vel, ptr.omega
            pvec[_RADIUS] = ptr.radius
        except (TypeError, ValueError):  # not 13 numbers
            return None
        mode = MODE_TOUCH
    if mode == MODE_TOUCH and cpl is not None:  # a pointer that grips
        if cpl is not fm.coupling[0]:  # checked once per Coupling (frozen)
            cvec = coupling_vector(cpl)
            if not 0 <= cpl.body < nb or cvec.shape != (16,):
                return None
            fm.coupling = (cpl, cvec, (MODE_GRIP, cpl.body, bool(cpl.position_only)))
        cvec, (mode, body, position_only) = fm.coupling[1], fm.coupling[2]
    flags = (mode, body, position_only, *loads)
    if flags != fm.flags:  # comparing costs a tenth of writing
        fm.ivec[:], fm.flags = flags, flags
    pins = _NO_PINS if not inp.pins else _pin_arrays(fm, inp.pins, nb)
    if pins is None:
        return None
    return _new_tuple(Input, (force, torque, pvec, cvec, fm.ivec, *pins))


def _pin_arrays(fm: FastModel, pins: tuple, nb: int) -> tuple | None:
    """(layout.PinVec rows, bones) of ``pins``, packed once per tuple of pins (a caller
    keeps its tuple while its pins do not change); None for pins the numpy step must judge
    (a bone out of range, two pins on one bone)."""
    if pins is fm.pin_cache[0]:
        return fm.pin_cache[1]
    try:
        bones = np.array([p.bone for p in pins], dtype=_I8)
        rows = np.array([np.concatenate((p.point, p.target, p.target_quat,
                                         (p.force_limit, p.torque_limit, float(p.orient))))
                         for p in pins], dtype=_F8).reshape(len(pins), -1)  # fmt: skip
    except (TypeError, ValueError, AttributeError):
        return None
    if rows.shape[1] != PinVec.SIZE or np.any((bones < 0) | (bones >= nb)):
        return None
    if len(np.unique(bones)) != len(bones):
        return None
    fm.pin_cache = (pins, (rows, bones))
    return fm.pin_cache[1]


def entry_point(dispatcher):
    """A caller of ``dispatcher`` that, once its one signature is compiled (or loaded from
    the cache), calls the compiled entry point directly, skipping numba's type
    resolution of every argument (their types never change: _arr and the packing
    normalise every array).  Returns the list whose item 0 is the function to call."""
    entry = [None]

    def first(*args):
        result = dispatcher(*args)
        if len(dispatcher.signatures) == 1:
            entry[0] = dispatcher.overloads[dispatcher.signatures[0]].entry_point
        return result

    entry[0] = first
    return entry


_KERNEL = entry_point(fast_kernel)


def new_state_arrays(nb: int, nj: int) -> tuple:
    """An uninitialised layout.StateSet for the kernel's out."""
    e = np.empty
    arrays = (e((nb, 3)), e((nb, 4)), e((nb, 3)), e((nb, 3)), e((nj, 3)), e(nj, _B1),
              e((nj, 4)), e(nj), e((nj, 3)), e(nb, _B1), e(nb), e((nb, 3)), e((nb, 4)),
              e((nb, 3)), e((nb, 3)), e((nj, 3)), e(3))  # fmt: skip
    return _new_tuple(StateSet, arrays)


def fast_step(
    fm: FastModel, state: State, inp: StepInput | None = None
) -> tuple[State, StepReport]:
    """Advance one step of size h of ``fm``'s model (``solver.compiled.pack.pack``),
    exactly as ``solver.pipeline.step``."""
    inp = inp or _NO_INPUT
    model = fm.model
    if fm.reason is not None:
        return step(model, state, inp)
    try:
        st, ins = _state_arrays(fm, state), _input_arrays(fm, inp)
    except (TypeError, ValueError, AttributeError):
        st = ins = None
    if st is None or ins is None:
        return step(model, state, inp)
    prev, keys, lam = st
    out, rep_f = new_state_arrays(len(prev.x), len(prev.q_sf)), np.empty(ReportFloat.SIZE)
    status, warm_key, warm_lam = _KERNEL[0](fm.flat, prev, keys, lam, ins, out, fm.rep_i, rep_f)
    if status:
        return step(model, state, inp)
    time, steps = state.time + model.options.h, state.step + 1
    new = _successor(state, time, steps, out, warm_key, warm_lam, bool(fm.iopt[IOpt.bdf2]))
    fm.last = (new, (out, warm_key, warm_lam))
    return new, with_pins(kernel_report(fm.rep_i, rep_f), inp.pins, new)


FIELDS = (
    "body_pos", "body_quat", "body_vel", "body_omega", "joint_q_sf", "joint_yielded",
    "joint_anchor", "joint_torque_avg", "joint_torque", "warm_key", "warm_lam",
    "body_asleep", "body_still",
)  # fmt: skip
"""State's fields after time and step, in their order: the kernel's out (x … τ), warm,
then the kernel's sleep arrays."""
STATE_SET_FIELDS = tuple(f for f in FIELDS if f not in ("warm_key", "warm_lam"))
"""The State fields of a layout.StateSet's arrays before its history, in its order."""
HISTORY_FIELDS = ("prev_pos", "prev_quat", "prev_vel", "prev_omega", "prev_q_sf")
"""The State fields of a layout.StateSet's history arrays (then hist: prev_h, prev_mark,
prev_load)."""


def _direct(cls, names: tuple) -> tuple | None:
    """The (name, default factory) of the fields of ``cls`` after ``names`` when
    ``cls(**values)`` sets the fields ``names`` from ``values`` and the rest from their
    defaults and does nothing else (a frozen dataclass's generated ``__init__``): then a
    new instance whose ``__dict__`` is filled in one call is the same object, as
    ``copy.copy`` and ``pickle`` make them, ~2–3 µs cheaper than that ``__init__``'s one
    object.__setattr__ per field.  None for any other class."""
    fields = dataclasses.fields(cls)
    if tuple(f.name for f in fields[: len(names)]) != names or hasattr(cls, "__post_init__"):
        return None
    rest = []
    for f in fields[len(names) :]:
        if f.default_factory is not dataclasses.MISSING:
            rest.append((f.name, f.default_factory))
        elif f.default is not dataclasses.MISSING:
            rest.append((f.name, lambda value=f.default: value))
        else:
            return None
    return None if "__slots__" in vars(cls) or not all(f.init for f in fields) else tuple(rest)


_NEW = object.__new__
_STATE_REST = _direct(State, ("time", "step", *FIELDS))
_REPORT_FIELDS = ("rows", "contacts", "iterations", "residual", "solver", "grip_force",
                  "grip_torque", "touch_force", "substeps", "pin_force", "pin_torque",
                  "pin_slip")  # fmt: skip
_DIRECT_REPORT = _direct(StepReport, _REPORT_FIELDS) == ()


def _successor(state: State, time: float, steps: int, out: StateSet, keys, lam,
               history: bool) -> State:  # fmt: skip
    """The State after ``state``: time, steps, the kernel's out, warm keys and λ, and
    out's history when ``history`` (BDF2; else the defaults: none) (a subclass of State
    keeps its other fields, as ``replace`` does)."""
    if type(state) is State and _STATE_REST is not None:
        new = _NEW(State)
        values = new.__dict__
        values.update(
            time=time, step=steps, body_pos=out.x, body_quat=out.q, body_vel=out.v,
            body_omega=out.omega, joint_q_sf=out.q_sf, joint_yielded=out.yielded,
            joint_anchor=out.anchor, joint_torque_avg=out.torque_avg, joint_torque=out.torque,
            warm_key=keys, warm_lam=lam, body_asleep=out.asleep, body_still=out.still,
        )  # fmt: skip
        for name, default in _STATE_REST:  # fields the kernel does not produce
            values[name] = default()
        if history:
            values.update(history_fields(out))
        return new
    arrays = dict(zip(STATE_SET_FIELDS, out, strict=False)) | {"warm_key": keys, "warm_lam": lam}
    if history:
        arrays |= history_fields(out)
    if type(state) is State:
        return State(time=time, step=steps, **arrays)
    return replace(state, time=time, step=steps, **arrays)


def history_fields(out: StateSet) -> dict:
    """The State's history fields of a StateSet's (solver.advance.bdf2)."""
    arrays = (out.prev_x, out.prev_q, out.prev_v, out.prev_omega, out.prev_q_sf)
    return dict(zip(HISTORY_FIELDS, arrays, strict=True)) | dict(
        prev_h=float(out.hist[0]), prev_mark=float(out.hist[1]), prev_load=float(out.hist[2])
    )


def kernel_report(rep_i: np.ndarray, rep_f: np.ndarray) -> StepReport:
    """The StepReport of the kernel's report arrays (rows, contacts, iterations, solver,
    substeps; residual, grip force, grip torque, touch force).  Its vectors are views of rep_f: pass
    an array of the caller's own."""
    rows, contacts, iterations, solver, substeps = rep_i.tolist()  # layout.ReportInt's order
    values = dict(
        rows=rows, contacts=contacts, iterations=iterations, residual=float(rep_f[_RESIDUAL]),
        solver=SOLVER_NAMES[solver], grip_force=rep_f[GRIP_FORCE], grip_torque=rep_f[GRIP_TORQUE],
        touch_force=rep_f[TOUCH_FORCE], substeps=substeps, pin_force=NO_PINS, pin_torque=NO_PINS,
        pin_slip=NO_SLIP,
    )  # fmt: skip
    if not _DIRECT_REPORT:
        return StepReport(**values)
    report = _NEW(StepReport)
    report.__dict__.update(values)
    return report
