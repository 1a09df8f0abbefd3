"""Substeps for joints under tension: the geometric stiffness the rows leave explicit.

A step linearises every joint row at the start of the step, so the rows' directions do
not turn with the bodies during the step.  A body whose joints pull on it with forces
f_j at levers r_j (from its centre of mass to the anchor) has, for a rotation θ about
an axis n ⟂ r_j, the potential |f_j|·|r_j|·(1 − cos θ): a rotational stiffness
k_j = |f_j||r_j| (N·m/rad) that the step treats explicitly.  Its mode

    ω_b² = Σ_j k_j / I⊥_j,     I⊥_j = least moment of inertia about axes ⟂ r_j,

is then integrated by an explicit scheme, stable only for h·ω_b below about 2.9
(measured: the 100-link rope of docs/stress.md, 2 cm 20 g links, blows up above
h = 3.8 ms where this formula gives 4.1 ms).  ``substeps_needed`` returns the number n
of equal substeps that keeps h·ω_b/n ≤ SAFE_RATE for every body, from the last step's
anchor forces (the warm-start forces of the anchor rows, which come first among the
sorted keys: kind 0, identity 3j + k), capped at ``max_substeps``.  For the doll at
h = 50 ms that is one; a light rope under its own weight at 5 ms needs two.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import replace
from functools import partial

import numpy as np

from solver.jit import kernel
from solver.kin_kernel import qexp, qmul, qnormalize
from solver.model import Model, kept_with
from solver.rows.grip import Pointer
from solver.state import State, StepInput, StepReport

SAFE_RATE = 2.0
"""h·ω per substep: below the measured stability edge (≈ 2.9) with a margin for tension
growing during the step."""


@kernel(error_model="numpy")
def _least_moment(inertia, b, r):
    """Least moment of body b's inertia about axes perpendicular to r (kg·m²), both in
    the body's frame."""
    rn = math.sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2])
    e = (r[0] / rn, r[1] / rn, r[2] / rn)
    t = (1.0, 0.0, 0.0) if abs(e[0]) < 0.9 else (0.0, 1.0, 0.0)
    u = (e[1] * t[2] - e[2] * t[1], e[2] * t[0] - e[0] * t[2], e[0] * t[1] - e[1] * t[0])
    un = math.sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2])
    u = (u[0] / un, u[1] / un, u[2] / un)
    v = (e[1] * u[2] - e[2] * u[1], e[2] * u[0] - e[0] * u[2], e[0] * u[1] - e[1] * u[0])
    a = c = s = 0.0
    for i in range(3):
        for k in range(3):
            a += u[i] * inertia[b, i, k] * u[k]
            c += v[i] * inertia[b, i, k] * v[k]
            s += u[i] * inertia[b, i, k] * v[k]
    return 0.5 * (a + c) - math.sqrt(0.25 * (a - c) ** 2 + s * s)


@kernel(error_model="numpy")
def tension_levers(joint_parent, joint_bone, anchor_parent, anchor_child, inv_mass, inertia):
    """(nj, 6) per joint, parent side then child side: |r| (m), 1/|r|² and I⊥/|r|²
    (0 where the side is the world, immovable, or has no lever), r the anchor in the
    side's own frame and I⊥ its least moment about axes perpendicular to r
    (``_least_moment``).  They are all that ``substeps_needed`` takes
    from the geometry, and none depends on the pose: a rotation keeps |r|, and the
    least moment about axes ⟂ r is the same whether r and I are both in the body's frame
    or both in the world's.  So they are made once per model."""
    nj = len(joint_parent)
    out = np.zeros((nj, 6))
    for j in range(nj):
        for side in range(2):
            b = joint_parent[j] if side == 0 else joint_bone[j]
            if b < 0 or inv_mass[b] <= 0.0:
                continue
            local = anchor_parent if side == 0 else anchor_child
            r = (local[j, 0], local[j, 1], local[j, 2])
            r2 = r[0] * r[0] + r[1] * r[1] + r[2] * r[2]
            out[j, 3 * side] = math.sqrt(r2)
            if r2 > 0.0:
                out[j, 3 * side + 1] = 1.0 / r2
                out[j, 3 * side + 2] = _least_moment(inertia, b, r) / r2
    return out


@kernel(error_model="numpy")
def _anchor_forces(nj, warm_key, warm_lam):
    """(nj,) |f_j| of the last step's anchor rows (0 where a joint has none yet)."""
    f = np.zeros(nj)
    for j in range(nj):
        if 3 * j + 2 < len(warm_key) and warm_key[3 * j + 2] == 3 * j + 2:
            x, y, z = warm_lam[3 * j], warm_lam[3 * j + 1], warm_lam[3 * j + 2]
            f[j] = math.sqrt(x * x + y * y + z * z)
    return f


@kernel(error_model="numpy", _nrt=True)
def substeps_needed(h, max_substeps, joint_parent, joint_bone, inv_mass, levers, warm_key,
                    warm_lam):  # fmt: skip
    """n ≥ 1 equal substeps for the step; 1 when max_substeps ≤ 1.  levers: the model's
    ``tension_levers``.

    Per body b, k_b = Σ_j |f_j||r_bj| over its joints.  Per joint between two movable
    bodies, the transverse motion u of the anchor turns each side by u/|r|, so the mode
    has ω_j² = Σ_sides k_b/|r_b|² / Σ_sides I⊥_b/|r_b|²: a light link between heavy ones
    is held by their inertia, equal links give ω² = k/I (the rope's zig-zag, module
    docstring).  A joint to the world or to an immovable body has no such mode."""
    nj = len(joint_parent)
    if max_substeps <= 1 or nj == 0:
        return 1
    f = _anchor_forces(nj, warm_key, warm_lam)
    k = np.zeros(len(inv_mass))
    for j in range(nj):
        p, c = joint_parent[j], joint_bone[j]
        if p >= 0:
            k[p] += f[j] * levers[j, 0]
        k[c] += f[j] * levers[j, 3]
    worst = 0.0
    for j in range(nj):
        p, c = joint_parent[j], joint_bone[j]
        if p < 0 or inv_mass[p] <= 0.0 or inv_mass[c] <= 0.0:
            continue
        stiff = k[p] * levers[j, 1] + k[c] * levers[j, 4]
        inertia = levers[j, 2] + levers[j, 5]
        if inertia > 0.0:
            worst = max(worst, stiff / inertia)
    return max(1, min(max_substeps, math.ceil(h * math.sqrt(worst) / SAFE_RATE)))


_LEVERS: dict[int, np.ndarray] = {}


def model_levers(model: Model) -> np.ndarray:
    """``tension_levers`` of ``model``, made once (kept while the model lives)."""

    def build() -> np.ndarray:
        return tension_levers(
            model.joint_parent, model.joint_bone, np.ascontiguousarray(model.joint_anchor_parent),
            np.ascontiguousarray(model.joint_anchor_child), model.body_inv_mass,
            np.ascontiguousarray(model.body_inertia),
        )  # fmt: skip

    return kept_with(model, _LEVERS, build)


def model_substeps(model: Model, state: State) -> int:
    """``substeps_needed`` for a step of ``model`` from ``state``."""
    o = model.options
    return substeps_needed(
        o.h, o.max_substeps, model.joint_parent, model.joint_bone, model.body_inv_mass,
        model_levers(model), state.warm_key, state.warm_lam,
    )  # fmt: skip


_SUB_MODELS: dict[tuple[int, int], Model] = {}


def sub_model(model: Model, n: int) -> Model:
    """``model`` at step h/n that never subdivides again (kept while ``model`` lives)."""
    build = partial(model.with_options, h=model.options.h / n, max_substeps=1)
    return kept_with(model, _SUB_MODELS, build, (id(model), n))


def pointer_at(ptr: Pointer | None, before_end: float) -> Pointer | None:
    """The step's pointer ``before_end`` seconds before the end of the step: its velocity
    is the step's mean, so its pose moves back along it (``moved_back``)."""
    if ptr is None or before_end == 0.0:
        return ptr
    f = np.float64
    pos, q = moved_back(np.asarray(ptr.pos, f), np.asarray(ptr.quat, f), np.asarray(ptr.vel, f),
                        np.asarray(ptr.omega, f), before_end)  # fmt: skip
    return replace(ptr, pos=np.array(pos), quat=np.array(q))


@kernel(error_model="numpy")
def moved_back(pos, q, vel, omega, before_end):
    """(position, quaternion) tuples of a pose (pos (3,), q (4,)) moving at (vel, omega)
    ``before_end`` seconds earlier: pos − t·vel, normalize(exp(−t·ω) ⊗ q).  The numpy
    step's ``pointer_at`` and the compiled step's parts (kernel.step_parts) both call it."""
    t = before_end
    back = (pos[0] - t * vel[0], pos[1] - t * vel[1], pos[2] - t * vel[2])
    turn = qexp((-t * omega[0], -t * omega[1], -t * omega[2]))
    return back, qnormalize(qmul(turn, (q[0], q[1], q[2], q[3])))


def run_substeps(
    model: Model, state: State, inp: StepInput, n: int, step_fn: Callable
) -> tuple[State, StepReport]:
    """One step of ``model`` as n steps of h/n by ``step_fn(n, state, input)`` (same loads
    and grip, the pointer along its mean velocity).  The State counts one step; errors
    name it."""
    return run_parts(model, state, inp, (n,) * n, step_fn)


def run_parts(
    model: Model, state: State, inp: StepInput, parts: tuple[int, ...], step_fn: Callable
) -> tuple[State, StepReport]:
    """One step of ``model`` as steps of h/d for each d of ``parts`` (their sum of 1/d is
    1), each by ``step_fn(d, state, input)`` on ``sub_model(model, d)`` (the pointer along
    its mean velocity to each part's end); the report as ``StepReport.substeps`` says."""
    h = model.options.h
    s, reports, done = state, [], 0.0
    for k, d in enumerate(parts):
        s = s if k == 0 else replace(s, step=state.step)
        done += h / d
        part = replace(inp, pointer=pointer_at(inp.pointer, max(h - done, 0.0)))
        s, rep = step_fn(d, s, part)
        reports.append(rep)
    last = reports[-1]
    report = replace(
        last,
        iterations=sum(r.iterations for r in reports),
        residual=max(r.residual for r in reports),
        grip_force=np.mean([r.grip_force for r in reports], axis=0),
        grip_torque=np.mean([r.grip_torque for r in reports], axis=0),
        touch_force=np.mean([r.touch_force for r in reports], axis=0),
        substeps=len(parts),
    )
    return replace(s, time=state.time + model.options.h, step=state.step + 1), report
