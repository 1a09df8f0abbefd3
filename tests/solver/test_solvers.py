"""PGS, direct and the dense reference solver on the same row tables."""

from __future__ import annotations

import functools
from dataclasses import replace

import numpy as np
import pytest
from rigbuild import chain, rheology

from solver import quat
from solver.advance.integrate import free_velocity
from solver.model import build_model
from solver.pipeline import step
from solver.rows.build import build_rows
from solver.rows.grip import Pointer, make_coupling
from solver.solve.direct import direct_solve
from solver.solve.dispatch import warm_start
from solver.solve.pgs import pgs_solve
from solver.solve.reference import reference_solve
from solver.solve.response import dense_system, regularize, row_response, world_inverse_inertia
from solver.spec import LimitSpec
from solver.state import StepInput, initial_state


def problem(model, state, inp=None):
    """The row table of the next step and what a solver needs."""
    inp = inp or StepInput()
    rot = quat.matrix(state.body_quat)
    inv_i = world_inverse_inertia(model.body_inv_inertia, rot)
    vel_free = free_velocity(model, state, inp, inv_i)
    rows, ncontact, _ = build_rows(model, state, rot, vel_free, inp)
    resp = row_response(rows, model.body_inv_mass, inv_i, model.options.h)
    rows = regularize(rows, resp, model.options.regularization)
    return rows, resp, vel_free, ncontact


@functools.cache
def contact_scene(seed: int):
    """A free chain of 2–4 balls with limits, tumbling onto the ground.

    One contact per body keeps the LCP's solution unique, even with friction, so
    the reference is *the* solution (with several redundant contacts per body, λ
    is not unique and PGS crawls along the degenerate direction).  The tumble itself
    runs on the default solver: it only makes the scene; the tests solve its next
    step.  Cached: every test reads the scene and none changes it.
    """
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 5))
    spec = chain(
        n,
        0.005,
        root_mode="free",
        lengths=rng.uniform(0.05, 0.2, n),
        radius=0.03,
        shape="sphere",
        collide=True,
        ground=0.97 - 0.02 * rng.random(),
        rheo=rheology(1.0, 0.1, 5.0),
        limits=LimitSpec(swing=np.radians(rng.uniform(5.0, 30.0)), twist=(-0.1, 0.1)),
    )
    model = build_model(spec)
    state = initial_state(model)
    state = replace(
        state,
        body_quat=quat.exp(rng.normal(scale=0.3, size=(n, 3))),
        body_omega=rng.normal(scale=2.0, size=(n, 3)),
    )
    for _ in range(40):
        state, _ = step(model, state)
    return model, state


def run_pgs(rows, resp, vel_free, iterations, lam0=None):
    lam0 = np.zeros(len(rows)) if lam0 is None else lam0
    return pgs_solve(
        rows.body_a, rows.body_b, rows.jac_a, rows.jac_b, resp[0], resp[1], rows.lo, rows.hi,
        rows.comp, rows.bias, rows.fric_of, rows.mu, vel_free, lam0, iterations, 0.0,
    )  # fmt: skip


def lcp_violation(q, c, lam, rows):
    """max |λ − proj(λ − r/d)|·d with r = Qλ + c from the dense matrices: 0 at a solution."""
    r = q @ lam + c
    lo, hi = rows.lo.copy(), rows.hi.copy()
    f = rows.fric_of >= 0
    lo[f] = -rows.mu[f] * lam[rows.fric_of[f]]
    hi[f] = -lo[f]
    d = np.diag(q)
    return np.max(np.abs(lam - np.clip(lam - r / d, lo, hi)) * d)


@pytest.mark.parametrize("seed", range(8))
def test_pgs_approaches_the_reference_as_iterations_grow(seed):
    # Frictionless contacts make the problem a convex QP: the velocities are unique
    # even though these scenes have more hard rows than degrees of freedom.
    model, state = contact_scene(seed)
    rows, resp, vel_free, ncontact = problem(model, state)
    assert ncontact > 0 and not rows.equality_only
    rows = replace(rows, mu=np.zeros(len(rows)))
    q, c = dense_system(rows, resp, vel_free)
    lam_ref = reference_solve(q, c, rows.lo, rows.hi, rows.fric_of, rows.mu)
    vel_ref = vel_free + _response(rows, resp, lam_ref, len(vel_free))
    errors = [
        np.abs(run_pgs(rows, resp, vel_free, n)[1] - vel_ref).max() for n in (3, 30, 300, 30000)
    ]
    assert errors[0] > 0.04, errors  # not trivial for PGS (measured ≥ 0.2 m/s)
    # measured ≤ 2.0e-9 m/s after 30,000 sweeps
    assert errors[-1] < 1e-8 and errors[-1] < errors[1] < errors[0], errors


@pytest.mark.parametrize("seed", range(8))
def test_pgs_with_friction_converges_to_the_solution_of_the_lcp(seed):
    # Friction bounds ±μλ_n depend on the solution.  Checks, all with the dense
    # matrices: PGS's limit satisfies the complementarity conditions; with the
    # friction bounds fixed at PGS's normal forces, the exact box-QP (unique: Q is
    # definite) gives the same forces; and where the reference's own damped
    # fixed-point iteration converges, it agrees too (it may fail to converge, as
    # a plain fixed point on friction can).
    model, state = contact_scene(seed)
    rows, resp, vel_free, _ = problem(model, state)
    q, c = dense_system(rows, resp, vel_free)
    # 100,000 sweeps: seed 2's rows are nearly redundant (cond Q ≈ 6e9), PGS converges
    # linearly and slowly there (1e-6 after 30,000 sweeps, 6e-15 after 100,000)
    sweeps = (3, 100_000)
    violation = [lcp_violation(q, c, run_pgs(rows, resp, vel_free, n)[0], rows) for n in sweeps]
    assert violation[-1] < 1e-10 < violation[0], violation  # measured ≤ 1.9e-11 (seed 6)
    lam = run_pgs(rows, resp, vel_free, sweeps[-1])[0]
    fixed = rows.fric_of >= 0
    bound = rows.mu[fixed] * lam[rows.fric_of[fixed]]
    lo, hi = rows.lo.copy(), rows.hi.copy()
    lo[fixed], hi[fixed] = -bound, bound
    no_friction_link = np.full(len(rows), -1)
    lam_qp = reference_solve(q, c, lo, hi, no_friction_link, rows.mu)
    # measured 8.5e-7 on seed 2 (cond Q ≈ 6e9: the reference's rounding, cond·ε), ≤ 3.7e-8
    # on the others
    assert np.abs(lam_qp - lam).max() < 1e-6 * max(1.0, np.abs(lam).max())
    lam_ref = reference_solve(q, c, rows.lo, rows.hi, rows.fric_of, rows.mu)
    if lcp_violation(q, c, lam_ref, rows) < 1e-9:  # (six seeds: ≤ 1.2e-10; 0.01 and 0.1 else)
        assert np.abs(lam_ref - lam).max() < 7.5e-8 * max(1.0, np.abs(lam).max())  # ≤ 1.5e-8


def _response(rows, resp, lam, nbody):
    dv = np.zeros((nbody + 1, 6))
    np.add.at(dv, rows.body_a, resp[0] * lam[:, None])
    np.add.at(dv, rows.body_b, resp[1] * lam[:, None])
    return dv[:-1]


@pytest.mark.parametrize("seed", range(4))
def test_direct_equals_reference_on_equality_only_scenes(seed):
    rng = np.random.default_rng(100 + seed)
    n = int(rng.integers(2, 8))
    model = build_model(
        chain(n, 0.01, lengths=rng.uniform(0.05, 0.3, n), rheo=rheology(2.0, 0.5, 3.0))
    )
    state = replace(initial_state(model), body_omega=rng.normal(size=(n, 3)))
    for _ in range(5):
        state, _ = step(model, state)
    rows, resp, vel_free, _ = problem(model, state)
    assert rows.equality_only
    lam, residual, ok = direct_solve(rows, resp, vel_free)
    assert ok
    q, c = dense_system(rows, resp, vel_free)
    lam_ref = reference_solve(q, c, rows.lo, rows.hi, rows.fric_of, rows.mu)
    assert np.abs(lam - lam_ref).max() <= 2e-8 * max(1.0, np.abs(lam_ref).max())  # 4.3e-9
    assert residual < 1.5e-14  # measured 2.7e-15


def sweeps_to_reach(model, warm: bool, tol: float) -> float:
    """Mean PGS sweeps per step needed to reach ``tol`` over a settling run."""
    m = model.with_options(method="pgs", iterations=500, warm_start=warm)
    state = initial_state(m)
    counts = []
    for k in range(200):
        rows, resp, vel_free, _ = problem(m, state)
        lam0 = warm_start(m, state, rows)
        _, _, sweeps, _ = pgs_solve(
            rows.body_a, rows.body_b, rows.jac_a, rows.jac_b, resp[0], resp[1], rows.lo,
            rows.hi, rows.comp, rows.bias, rows.fric_of, rows.mu, vel_free, lam0, 500, tol,
        )  # fmt: skip
        state, _ = step(m, state)
        if k >= 50:
            counts.append(sweeps)
    return float(np.mean(counts))


def test_warm_start_needs_fewer_iterations():
    model = build_model(chain(6, 0.005, collide=True, ground=0.95, rheo=rheology(2.0, 0.2, 5.0)))
    cold = sweeps_to_reach(model, False, 1e-4)
    warm = sweeps_to_reach(model, True, 1e-4)
    assert warm < 0.08 * cold, (warm, cold)  # measured 7 and 449 sweeps a step (0.016)


@pytest.mark.parametrize("limit", [0.5, 2.0, 1e6])
def test_direct_solve_with_a_saturated_grip_equals_the_reference(limit):
    # A grip pulling a chain's tip 30 cm away: with a low force limit the coupling
    # rows saturate; the active-set direct solve must match the exact box-QP.
    model = build_model(chain(5, 0.005, rheo=rheology(2.0, 0.5, 3.0)))
    state = initial_state(model)
    tip = np.array([0.5, 1.0, 0.0])
    ptr = Pointer(tip + [0.0, 0.3, 0.0], quat.IDENTITY, np.zeros(3), np.zeros(3))
    here = Pointer(tip, quat.IDENTITY, np.zeros(3), np.zeros(3))
    coupling = make_coupling(
        state, here, 4, tip, stiffness=2000.0, damping=40.0, rot_stiffness=50.0,
        rot_damping=2.0, force_limit=limit, torque_limit=limit,
    )  # fmt: skip
    rows, resp, vel_free, _ = problem(model, state, StepInput(pointer=ptr, coupling=coupling))
    assert rows.bilateral
    lam, _, ok = direct_solve(rows, resp, vel_free)
    q, c = dense_system(rows, resp, vel_free)
    lam_ref = reference_solve(q, c, rows.lo, rows.hi, rows.fric_of, rows.mu)
    assert ok
    assert np.abs(lam - lam_ref).max() <= 4e-9 * max(1.0, np.abs(lam_ref).max())  # 7.6e-10
    saturated = np.isclose(np.abs(lam), limit)
    assert saturated.any() == (limit < 100.0)
