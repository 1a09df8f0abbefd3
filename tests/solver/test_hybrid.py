"""The hybrid solver (solver.solve.hybrid): joints exact, bounded rows by PGS on their Schur
complement; checked against the dense reference (BVLS), the dense LCP conditions, PGS
on the same table, and the exact joint equations."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from rigbuild import chain, rheology
from test_solvers import contact_scene, lcp_violation, problem, run_pgs

from puppetcli.bench.stress_scenes import free_bodies
from solver import quat
from solver.model import build_model
from solver.pipeline import step
from solver.rows.grip import Pointer, make_coupling
from solver.rows.table import KIND_FRICTION, KIND_GRIP, take_rows
from solver.solve import hybrid
from solver.solve.hybrid import dormant_rows, equality_rows, hybrid_solve, leaf_contacts
from solver.solve.pgs import dense_pgs
from solver.solve.reference import reference_solve
from solver.solve.response import dense_system
from solver.spec import ShapeSpec
from solver.state import StepInput, initial_state


def velocities(rows, resp, vel_free, lam):
    vel = np.vstack((vel_free, np.zeros((1, 6))))
    np.add.at(vel, rows.body_a, resp[0] * lam[:, None])
    np.add.at(vel, rows.body_b, resp[1] * lam[:, None])
    return vel[:-1]


@pytest.mark.parametrize("seed", range(8))
def test_hybrid_reaches_the_reference_without_friction(seed):
    # Frictionless: a convex QP with unique velocities; the reference is exact (BVLS).
    model, state = contact_scene(seed)
    rows, resp, vel_free, ncontact = problem(model, state)
    assert ncontact > 0 and equality_rows(rows).any() and not equality_rows(rows).all()
    rows = replace(rows, mu=np.zeros(len(rows)))
    q, c = dense_system(rows, resp, vel_free)
    vel_ref = velocities(rows, resp, vel_free, reference_solve(q, c, rows.lo, rows.hi,
                                                               rows.fric_of, rows.mu))  # fmt: skip
    lam, _, _ = hybrid_solve(rows, resp, vel_free, np.zeros(len(rows)), 2000)
    assert np.abs(velocities(rows, resp, vel_free, lam) - vel_ref).max() < 1e-8  # ≤ 2.0e-9


@pytest.mark.parametrize("seed", range(8))
def test_hybrid_with_friction_solves_the_lcp(seed):
    model, state = contact_scene(seed)
    rows, resp, vel_free, _ = problem(model, state)
    q, c = dense_system(rows, resp, vel_free)
    # 20,000 sweeps: seed 2's bounded rows are nearly redundant and converge slowly
    lam, _, residual = hybrid_solve(rows, resp, vel_free, np.zeros(len(rows)), 20_000)
    assert lcp_violation(q, c, lam, rows) < 5e-12  # measured ≤ 1.0e-12 over the 8 seeds
    assert residual < 5e-12


def without_friction(rows, resp):
    """The table and responses without friction rows: frictionless contacts."""
    keep = rows.kind != KIND_FRICTION
    return take_rows(rows, keep), (resp[0][keep], resp[1][keep])


@pytest.mark.parametrize("seed", range(8))
def test_frictionless_ground_contacts_are_solved_exactly_with_the_joints(seed):
    # Without friction rows each ball's contact with the ground is a leaf contact,
    # eliminated with the joints; the contacts between balls and the limits are iterated.
    model, state = contact_scene(seed)
    rows, resp, vel_free, _ = problem(model, state)
    rows, resp = without_friction(rows, resp)
    leaf = leaf_contacts(rows)
    assert leaf.any() and not leaf[equality_rows(rows)].any()
    q, c = dense_system(rows, resp, vel_free)
    lam_ref = reference_solve(q, c, rows.lo, rows.hi, rows.fric_of, rows.mu)
    lam, _, _ = hybrid_solve(rows, resp, vel_free, np.zeros(len(rows)), 2000)
    vel, vel_ref = (velocities(rows, resp, vel_free, x) for x in (lam, lam_ref))
    assert np.abs(vel - vel_ref).max() < 1e-8  # measured ≤ 2.0e-9
    # One sweep: the pushing leaf contacts hold exactly, as the joints do, whatever λ_U.
    lam, _, _ = hybrid_solve(rows, resp, vel_free, np.zeros(len(rows)), 1)
    push = leaf & (lam > 0.0)
    r = q @ lam + c
    assert push.any() and (lam[leaf] >= 0.0).all()
    assert np.abs(r[push]).max() < 1e-16 * np.abs(c).max()  # measured ≤ 5.0e-18


def test_sticking_ground_contacts_are_solved_exactly_with_the_joints(monkeypatch):
    # With friction, a ball's contact with the ground is a leaf contact while it sticks:
    # its normal and friction rows are eliminated with the joints, so after one sweep
    # they hold exactly (r = 0) inside the friction pyramid, whatever λ_U.  Warm-started
    # from the solution (contacts that pushed last step and did not slide start in the
    # forest: iterated_first); a contact of each of the 8 scenes sticks.
    exact_sets = []
    round_ = hybrid._round

    def watched(rows, q, c, lam0, exact, *args):
        exact_sets.append(exact)
        return round_(rows, q, c, lam0, exact, *args)

    monkeypatch.setattr(hybrid, "_round", watched)
    sticking = 0
    for seed in range(8):
        rows, resp, vel_free, _ = problem(*contact_scene(seed))
        assert (rows.kind == KIND_FRICTION).any()
        q, c = dense_system(rows, resp, vel_free)
        warm = reference_solve(q, c, rows.lo, rows.hi, rows.fric_of, rows.mu)
        lam, _, _ = hybrid_solve(rows, resp, vel_free, warm, 1)
        stuck = exact_sets[-1] & leaf_contacts(rows)
        r = q @ lam + c
        assert np.abs(r[stuck]).max(initial=0.0) < 1e-16 * np.abs(c).max()  # ≤ 1.8e-17
        normal = np.where(rows.fric_of >= 0, rows.fric_of, np.arange(len(rows)))
        rubbing = stuck & (rows.fric_of >= 0)
        assert (lam[stuck & (rows.fric_of < 0)] > 0.0).all()
        assert (np.abs(lam[rubbing]) <= rows.mu[rubbing] * lam[normal[rubbing]]).all()
        sticking += stuck.any()
    assert sticking == 8


def test_a_leaf_contact_that_would_pull_is_held_at_zero():
    # A ball 1 mm into a frictionless ground, leaving it at 1 m/s: its contact is not
    # dormant (it asks for a push out of the ground), but the exact solve would pull the
    # ball back (λ < 0); the contact is pinned at λ = 0 and the ball flies on.
    ball = ShapeSpec("sphere", radius=0.05)
    model = free_bodies([(ball, np.array([0.0, 0.044, 0.0]), np.array([0.0, 0.054, 0.0]))],
                        0.005, gravity=True, ground=True)  # fmt: skip
    state = replace(initial_state(model), body_vel=np.array([[0.0, 1.0, 0.0]]))
    rows, resp, vel_free, ncontact = problem(model, state)
    rows, resp = without_friction(rows, resp)
    assert ncontact == 1 and leaf_contacts(rows).all() and rows.bias[0] < 0.0
    lam0 = np.zeros(len(rows))
    assert not dormant_rows(rows, lam0).any()
    q, c = dense_system(rows, resp, vel_free)
    assert -c[0] / q[0, 0] < 0.0  # the exact row alone would pull
    lam_ref = reference_solve(q, c, rows.lo, rows.hi, rows.fric_of, rows.mu)
    lam, _, _ = hybrid_solve(rows, resp, vel_free, lam0, 200)
    assert lam[0] == 0.0 == lam_ref[0]
    assert np.array_equal(velocities(rows, resp, vel_free, lam), vel_free)


@pytest.mark.parametrize("sweeps", [1, 3, 15])
def test_joint_rows_hold_exactly_whatever_the_sweeps(sweeps):
    # The E rows are solved by elimination given λ_U, so r_E = (Qλ + c)_E vanishes to
    # rounding after any number of sweeps; PGS with as many sweeps leaves them open.
    model, state = contact_scene(3)
    rows, resp, vel_free, _ = problem(model, state)
    q, c = dense_system(rows, resp, vel_free)
    eq = equality_rows(rows)
    lam, _, _ = hybrid_solve(rows, resp, vel_free, np.zeros(len(rows)), sweeps)
    scale = np.abs(c[eq]).max()
    assert np.abs(q[eq] @ lam + c[eq]).max() < 1e-14 * scale  # measured ≤ 1.9e-15
    lam_pgs = run_pgs(rows, resp, vel_free, sweeps)[0]
    assert np.abs(q[eq] @ lam_pgs + c[eq]).max() > 2.5e-3 * scale  # measured ≥ 0.0136


def test_without_joints_the_hybrid_is_pgs_on_the_dense_system():
    # Free balls on the ground: no equality rows, S = Q, and dense_pgs's sweeps are
    # PGS's sweeps (the same Gauss–Seidel order and projection).
    ball = ShapeSpec("sphere", radius=0.05)
    shapes = [(ball, np.array([0.09 * i, 0.03, 0.0]), np.array([0.09 * i, 0.07, 0.0]))
              for i in range(3)]  # fmt: skip
    model = free_bodies(shapes, 0.005, gravity=True, ground=True)
    state = initial_state(model)
    rows, resp, vel_free, ncontact = problem(model, state)
    assert ncontact >= 3 and not equality_rows(rows).any()
    q, c = dense_system(rows, resp, vel_free)
    for sweeps in (1, 2, 7):
        lam_dense = dense_pgs(q, c, rows.lo, rows.hi, rows.fric_of, rows.mu,
                              np.zeros(len(rows)), sweeps, 0.0)[0]  # fmt: skip
        lam_pgs = run_pgs(rows, resp, vel_free, sweeps)[0]
        assert np.abs(lam_dense - lam_pgs).max() <= 1e-15 * max(1.0, np.abs(lam_pgs).max())


def test_auto_uses_hybrid_with_contacts_and_direct_without():
    model = build_model(chain(4, 0.005, collide=True, ground=0.97))
    state = initial_state(model)
    solvers = set()
    for _ in range(60):
        state, report = step(model, state)
        solvers.add(report.solver)
    assert solvers == {"direct", "hybrid"}
    bare = build_model(chain(4, 0.005, rheo=rheology(1.0, 0.1, 5.0)))
    assert step(bare, initial_state(bare))[1].solver == "direct"


def test_a_dormant_contact_wakes_when_the_body_would_cross_it():
    # A ball 5 mm above the ground falling at 2 m/s, h = 5 ms: its speculative contact
    # (no force last step, bias = gap/h = 1 m/s > 0) starts dormant; the solve finds
    # the ball would cross, wakes it, and the ball lands with the reference's velocity:
    # the approach the speculative row allows, gap/h.
    ball = ShapeSpec("sphere", radius=0.05)
    model = free_bodies([(ball, np.array([0.0, 0.05, 0.0]), np.array([0.0, 0.06, 0.0]))], 0.005,
                        gravity=True, ground=True)  # fmt: skip
    state = replace(initial_state(model), body_vel=np.array([[0.0, -2.0, 0.0]]))
    gap = float(state.body_pos[0, 1]) - 0.05
    rows, resp, vel_free, ncontact = problem(model, state)
    assert ncontact == 1 and gap == pytest.approx(0.005)
    lam0 = np.zeros(len(rows))
    assert dormant_rows(rows, lam0).all()
    q, c = dense_system(rows, resp, vel_free)
    lam_ref = reference_solve(q, c, rows.lo, rows.hi, rows.fric_of, rows.mu)
    lam, _, _ = hybrid_solve(rows, resp, vel_free, lam0, 200)
    assert lam[0] > 0.0
    vel = velocities(rows, resp, vel_free, lam)
    assert np.abs(vel - velocities(rows, resp, vel_free, lam_ref)).max() < 5.5e-11  # 1.1e-11
    # measured 1.05e-6: the 1e-6 regularisation
    assert vel[0, 1] == pytest.approx(-gap / model.options.h, rel=5e-6)


@pytest.mark.parametrize("limit", [0.05, 0.3, 1e6])
def test_grip_at_its_force_limit_with_contacts_equals_the_reference(limit):
    # contact_scene's balls on the ground (one contact each, frictionless: unique
    # forces) with a grip pulling the last ball up and sideways: the hybrid pins the
    # saturated grip rows as the direct solve does and matches the exact box-QP.
    model, state = contact_scene(5)
    b = model.nbody - 1
    centre = state.body_pos[b]
    here = Pointer(centre, quat.IDENTITY, np.zeros(3), np.zeros(3))
    coupling = make_coupling(state, here, b, centre, stiffness=2000.0, damping=40.0,
                             rot_stiffness=50.0, rot_damping=2.0, force_limit=limit,
                             torque_limit=limit)  # fmt: skip
    ptr = Pointer(centre + [0.05, 0.3, 0.0], quat.IDENTITY, np.zeros(3), np.zeros(3))
    inp = StepInput(pointer=ptr, coupling=coupling)
    rows, resp, vel_free, ncontact = problem(model, state, inp)
    assert ncontact > 0
    rows = replace(rows, mu=np.zeros(len(rows)))
    q, c = dense_system(rows, resp, vel_free)
    lam_ref = reference_solve(q, c, rows.lo, rows.hi, rows.fric_of, rows.mu)
    lam, _, _ = hybrid_solve(rows, resp, vel_free, np.zeros(len(rows)), 3000)
    vel, vel_ref = (velocities(rows, resp, vel_free, x) for x in (lam, lam_ref))
    assert np.abs(vel - vel_ref).max() < 4e-8  # measured ≤ 7.6e-9
    grip = rows.kind == KIND_GRIP
    assert np.isclose(np.abs(lam[grip]), limit).any() == (limit < 100.0)
