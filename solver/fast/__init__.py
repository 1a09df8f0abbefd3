"""The compiled step: ``fast_step`` is ``solver.step.step`` in one numba call.

    from solver.fast import fast_step, supports
    step_fn = fast_step if supports(model, inp) else solver.step.step
    state, report = step_fn(model, state, inp)

Same pipeline, rows, row order, warm start by row key, solvers (direct by an exact
linear-time elimination over the joint tree, PGS by ``solver.pgs``'s kernel), the same
State and StepReport, and the same errors: whenever the compiled step meets something
it does not do itself — a box–box contact, a step the monitor rejects (non-finite,
energy blow-up, joint torn apart), a degenerate direct system, inputs of unexpected
shapes — it hands that step to ``solver.step.step``, which then raises the usual
SimulationError (step, time, bone) or computes the step.  Results agree with the numpy
step to rounding (the tests compare them).

Not compiled (``supports`` is False, ``fast_step`` simply runs the numpy step):
method "reference", and box–box pairs that involve a movable body.

The first call in a fresh checkout compiles the kernels (numba, cached on disk in
``solver/fast/__pycache__``); later processes load them from the cache.  A FastModel
holds workspaces: one model, one thread at a time.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from solver.fast.cache import ensure_fresh_cache

ensure_fresh_cache()

from solver.fast.kernel import MODE_GRIP, MODE_TOUCH, SUBSTEP, step_kernel  # noqa: E402
from solver.fast.pack import FastModel, fast_model  # noqa: E402
from solver.model import Model  # noqa: E402
from solver.state import State, StepInput, StepReport  # noqa: E402
from solver.step import step  # noqa: E402
from solver.substep import run_substeps  # noqa: E402

__all__ = ["fast_model", "fast_step", "supports"]

SOLVER_NAMES = ("direct", "pgs", "hybrid")
_F8, _I8, _B1 = np.dtype(np.float64), np.dtype(np.int64), np.dtype(np.bool_)
_NO_VEC = np.zeros(16)  # the pointer / coupling argument when there is none (never read)


def supports(model: Model, inp: StepInput | None = None) -> bool:
    """True when ``fast_step`` compiles this model's steps (any StepInput is accepted)."""
    return fast_model(model).reason is None


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
    """The kernel's state tuple; the one fast_step returned last is trusted as is."""
    if state is fm.last[0]:
        return fm.last[1]
    nb, nj = len(fm.m[15]), len(fm.m[0])
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
    nw = np.shape(state.warm_key)[:1]
    st = (*arrays, _arr(state.warm_key, _I8, nw), _arr(state.warm_lam, _F8, nw))
    return None if any(a is None for a in st) else st


def _input_arrays(fm: FastModel, inp: StepInput) -> tuple | None:
    """The kernel's input tuple (force, torque, pointer, coupling, flags)."""
    nb = len(fm.m[15])
    ivec = np.zeros(5, np.int64)
    force = torque = fm.zeros
    if inp.body_force is not None:
        force, ivec[3] = _arr(inp.body_force, _F8, (nb, 3)), 1
    if inp.body_torque is not None:
        torque, ivec[4] = _arr(inp.body_torque, _F8, (nb, 3)), 1
    if force is None or torque is None:
        return None
    ptr, cpl = inp.pointer, inp.coupling
    if ptr is None or (cpl is None and not ptr.radius > 0.0):
        return force, torque, _NO_VEC, _NO_VEC, ivec
    pvec = np.concatenate((ptr.pos, ptr.quat, ptr.vel, ptr.omega, (ptr.radius,)), dtype=_F8)
    if pvec.shape != (14,):
        return None
    if cpl is None:
        ivec[0] = MODE_TOUCH
        return force, torque, pvec, _NO_VEC, ivec
    if not 0 <= cpl.body < nb:
        return None
    if cpl is not fm.coupling[0]:
        cvec = np.concatenate(
            (
                cpl.anchor,
                cpl.offset,
                cpl.rest,
                (
                    cpl.stiffness,
                    cpl.damping,
                    cpl.rot_stiffness,
                    cpl.rot_damping,
                    cpl.force_limit,
                    cpl.torque_limit,
                ),
            ),
            dtype=_F8,
        )
        fm.coupling = (cpl, cvec)
    ivec[:3] = MODE_GRIP, cpl.body, bool(cpl.position_only)
    return (force, torque, pvec, fm.coupling[1], ivec) if fm.coupling[1].shape == (16,) else None


def _kernel(*args):
    """step_kernel; after the first call its compiled entry point, skipping the dispatcher's
    type resolution (the argument types never change: _arr normalises every array)."""
    result = step_kernel(*args)
    if len(step_kernel.signatures) == 1:
        _ENTRY[0] = step_kernel.overloads[step_kernel.signatures[0]].entry_point
    return result


_ENTRY = [_kernel]


def fast_step(model: Model, state: State, inp: StepInput | None = None) -> tuple[State, StepReport]:
    """Advance one step of size model.options.h, exactly as ``solver.step.step``."""
    inp = inp or StepInput()
    fm = fast_model(model)
    if fm.reason is not None:
        return step(model, state, inp)
    try:
        st, ins = _state_arrays(fm, state), _input_arrays(fm, inp)
    except (TypeError, ValueError, AttributeError):
        st = ins = None
    if st is None or ins is None:
        return step(model, state, inp)
    status, out, warm_key, warm_lam, rep_i, rep_f = _ENTRY[0](
        fm.m, fm.g, fm.tree, fm.ptree, fm.ws, fm.pws, fm.opt, fm.iopt, st, ins
    )
    if status == SUBSTEP:
        return run_substeps(model, state, inp, int(rep_i[0]), fast_step)
    if status:
        return step(model, state, inp)
    fields = dict(
        time=state.time + model.options.h,
        step=state.step + 1,
        body_pos=out[0],
        body_quat=out[1],
        body_vel=out[2],
        body_omega=out[3],
        joint_q_sf=out[4],
        joint_yielded=out[5],
        joint_anchor=out[6],
        joint_torque_avg=out[7],
        joint_torque=out[8],
        warm_key=warm_key,
        warm_lam=warm_lam,
    )
    new = State(**fields) if type(state) is State else replace(state, **fields)
    fm.last = (new, (*out[:8], warm_key, warm_lam))
    return new, kernel_report(rep_i, rep_f)


def kernel_report(rep_i: np.ndarray, rep_f: np.ndarray) -> StepReport:
    """The StepReport of the kernel's report arrays (rows, contacts, iterations, solver;
    residual, grip force, grip torque, touch force)."""
    return StepReport(
        int(rep_i[0]), int(rep_i[1]), int(rep_i[2]), float(rep_f[0]), SOLVER_NAMES[rep_i[3]],
        rep_f[1:4].copy(), rep_f[4:7].copy(), rep_f[7:10].copy(),
    )  # fmt: skip
