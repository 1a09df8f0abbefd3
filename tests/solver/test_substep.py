"""Substeps for joints under tension (solver.advance.substep): the criterion against its closed
form, the substepped step against its parts, and the rope that needs it."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from rigbuild import chain

from puppetcli.bench import stress
from solver import quat
from solver.advance.substep import model_substeps, pointer_at, run_substeps, sub_model
from solver.engine import Engine
from solver.model import build_model
from solver.pipeline import step
from solver.rows.grip import Pointer
from solver.state import State, StepInput, initial_state

SAFE_RATE = 2.0
"""h·ω per substep the step promises to stay below (docs/stress.md): the explicit
integration of a joint's tension mode is unstable above about 2.9 (measured on the 100-link
rope), 2 keeps a margin for tension growing during the step.  Stated here, not imported."""


def needed_in_world(model, state: State) -> int:
    """The module docstring's count written out in the world frame at the state's pose:
    levers R_b r_j, world inertia R I Rᵀ and its least moment about the axes ⟂ the lever
    from numpy's eigen-solver on the 2×2 block of that plane."""
    rot = quat.matrix(state.body_quat)
    inertia_w = rot @ model.body_inertia @ np.swapaxes(rot, 1, 2)
    nj, movable = model.njoint, model.body_inv_mass > 0.0
    f = np.zeros(nj)
    for j in range(nj):
        if 3 * j + 2 < len(state.warm_key) and state.warm_key[3 * j + 2] == 3 * j + 2:
            f[j] = np.linalg.norm(state.warm_lam[3 * j : 3 * j + 3])
    sides = lambda j: ((model.joint_parent[j], model.joint_anchor_parent[j]),  # noqa: E731
                       (model.joint_bone[j], model.joint_anchor_child[j]))  # fmt: skip
    k = np.zeros(model.nbody)
    for j in range(nj):
        for b, local in sides(j):
            if b >= 0 and movable[b]:
                k[b] += f[j] * np.linalg.norm(rot[b] @ local)
    worst = 0.0
    for j in range(nj):
        if model.joint_parent[j] < 0 or not movable[model.joint_parent[j]]:
            continue
        if not movable[model.joint_bone[j]]:
            continue
        stiff = inertia = 0.0
        for b, local in sides(j):
            r = rot[b] @ local
            plane = np.linalg.svd(r[None])[2][1:]  # two unit axes ⟂ r
            stiff += k[b] / (r @ r)
            inertia += np.linalg.eigvalsh(plane @ inertia_w[b] @ plane.T)[0] / (r @ r)
        worst = max(worst, stiff / inertia)
    n = math.ceil(model.options.h * math.sqrt(worst) / SAFE_RATE)
    return max(1, min(model.options.max_substeps, n))


def with_anchor_force(model, force: float) -> State:
    """The rest state with a last-step force of ``force`` N on joint 0's anchor rows."""
    nj = model.njoint
    lam = np.zeros(3 * nj)
    lam[0] = force
    return replace(initial_state(model), warm_key=np.arange(3 * nj, dtype=np.int64), warm_lam=lam)


@pytest.mark.parametrize("target", [1, 2, 4, 9])
def test_two_free_links_need_the_closed_form_count(target):
    # Two equal links (L = 0.1 m) joined at their ends, nothing else: each side has the
    # lever L/2 and k = f·L/2, so ω² = (2k/r²)/(2I⊥/r²) = f·L/(2 I⊥), I⊥ the transverse
    # moment, and n = ceil(h·ω/SAFE_RATE).  Pick f for h·ω/SAFE_RATE = target − 0.5.
    model = build_model(chain(2, 0.005, root_mode="free", gravity=(0, 0, 0)))
    transverse = np.linalg.eigvalsh(model.body_inertia[0])[-1]
    omega = (target - 0.5) * SAFE_RATE / model.options.h
    force = omega**2 * 2.0 * transverse / 0.1
    state = with_anchor_force(model, force)
    assert model_substeps(model, state) == target
    assert model_substeps(model.with_options(max_substeps=3), state) == min(target, 3)
    assert model_substeps(model.with_options(max_substeps=1), state) == 1


@pytest.mark.parametrize("seed", range(4))
def test_the_count_is_the_world_frame_count_at_any_pose(seed):
    # The levers are made once, in the bodies' frames; the world-frame formula at a
    # random pose of a random chain (links of 1–10 cm, random anchor forces spanning
    # 1–30 substeps) must give the same count, step for step.
    rng = np.random.default_rng(seed)
    lengths = rng.uniform(0.01, 0.1, size=5).tolist()
    model = build_model(chain(5, float(rng.uniform(0.002, 0.02)), root_mode="free",
                              lengths=lengths))  # fmt: skip
    model = model.with_options(max_substeps=64)
    nj, counts = model.njoint, set()
    for _ in range(40):
        q = quat.normalize(rng.normal(size=(model.nbody, 4)))
        lam = rng.normal(size=3 * nj) * 10.0 ** rng.uniform(-1, 4, size=3 * nj)
        state = replace(initial_state(model), body_quat=q, warm_lam=lam,
                        warm_key=np.arange(3 * nj, dtype=np.int64))  # fmt: skip
        counts.add(model_substeps(model, state))
        assert model_substeps(model, state) == needed_in_world(model, state)
    assert len(counts) > 3  # the poses and forces span several counts


def test_a_joint_to_the_world_has_no_tension_mode():
    # One link hanging from a fixed stand by its joint: the anchor cannot move sideways.
    model = build_model(chain(1, 0.05, root_mode="ball"))
    assert model_substeps(model, with_anchor_force(model, 1e6)) == 1


def test_pointer_moves_back_along_its_mean_velocity():
    rotvec = np.array([0.0, 0.0, 2.0])
    ptr = Pointer(np.array([1.0, 2.0, 3.0]), quat.exp(rotvec * 0.01), np.array([0.5, 0.0, -1.0]),
                  rotvec, 0.01)  # fmt: skip
    back = pointer_at(ptr, 0.004)
    assert np.allclose(back.pos, [0.998, 2.0, 3.004], atol=1e-15)
    assert np.allclose(back.quat, quat.exp(rotvec * 0.006), atol=1e-15)
    assert (back.vel is ptr.vel) and back.radius == ptr.radius


def test_a_substepped_step_is_its_substeps():
    # A falling chain with a push: run_substeps(n) = n steps of h/n of the same input,
    # counted as one step; iterations add up.
    model = build_model(chain(3, 0.01))
    force = np.zeros((3, 3))
    force[2] = [0.0, 5.0, 0.0]
    inp = StepInput(body_force=force)
    state = initial_state(model)
    whole, report = run_substeps(
        model, state, inp, 4, lambda d, s, i: step(sub_model(model, d), s, i)
    )
    sub = model.with_options(h=0.0025, max_substeps=1)
    parts = state
    iterations = 0
    for _ in range(4):
        parts, r = step(sub, parts, inp)
        iterations += r.iterations
    assert np.array_equal(whole.body_pos, parts.body_pos)
    assert (whole.step, whole.time) == (1, pytest.approx(0.01, abs=1e-18))
    assert report.substeps == 4 and report.iterations == iterations


def test_the_rope_needs_substeps_and_is_stable_with_them():
    # The 100-link rope of 2 cm, 20 g links at h = 5 ms: beyond the tension limit
    # h ≈ 0.85·sqrt(m·L/T) (docs/stress.md) without substeps.
    scene = stress.chain_100_rope()
    one = replace(scene, model=scene.model.with_options(max_substeps=1))
    assert not stress.run_scene(one).stable
    res = stress.run_scene(scene)
    assert res.stable, res.problems
    model, state, counts = scene.model, scene.start, []
    engine = Engine(model)
    for _ in range(round(scene.duration / model.options.h)):
        state, report = engine.step(state)
        counts.append(report.substeps)
    assert max(counts) >= 2 and counts[0] == 1
    assert math.isclose(state.time, scene.duration, rel_tol=1e-12)
