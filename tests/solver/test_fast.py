"""The compiled step (solver.compiled.fast) against the numpy step, an independent implementation.

Both run side by side from the same state with the same inputs; every step's state
must agree to 1.2e-10 and every step's report must match.  Row forces (λ, joint torques,
grip and touch forces) are compared to 8.5e-9 relative to the largest: the components of
λ along nearly redundant rows (a body held by joint, limit and contact rows at once)
are fixed only by the 10⁻⁶ regularisation, which amplifies rounding by ~10⁶, while the
velocities they produce are not affected.  Measured over this module's runs and
tests/solver/test_sleep.py's: states ≤ 2.4e-11 (the substepped rope; 7.4e-11 for a step
of the box stack, its four redundant corners on a sleeping box), forces ≤ 1.7e-9 (the 30
resting contacts); the bounds are 5× the first and the last, 1.6× the stack's.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from paper_experiment import DD, DF, INERTIA, KF, T_END, T_LOAD, TAU, recursion
from rigbuild import chain, one_bone, rheology

from puppetcli.bench.stages import scene_inputs
from puppetcli.rig.load import load_rig
from solver import quat
from solver.advance.stabilize import project_joints, projection_tol
from solver.compiled import sim as sim_module
from solver.compiled.fast import supports
from solver.compiled.pack import pack
from solver.engine import Engine
from solver.errors import SimulationError
from solver.model import build_model
from solver.observe import bone_points, joint_gaps, joint_rotations
from solver.pipeline import step
from solver.rows.grip import Pointer, make_coupling
from solver.rows.pin import make_pin
from solver.solve import hybrid
from solver.solve.hybrid_kernel import NU_CAP
from solver.spec import BoneSpec, GroundSpec, LimitSpec, PropSpec, RigSpec, ShapeSpec
from solver.state import StepInput, initial_state

DOLL = Path(__file__).resolve().parents[2] / "rigs" / "doll.yaml"
TOL, FORCE_TOL = 1.2e-10, 8.5e-9
STATE = ("body_pos", "body_quat", "body_vel", "body_omega", "joint_q_sf", "joint_anchor")
FORCES = ("joint_torque_avg", "joint_torque", "warm_lam")


def close(a, b, scale: bool = False) -> bool:
    """|a − b| ≤ TOL, or with scale ≤ FORCE_TOL·max(1, |a|) (forces)."""
    a, b = np.asarray(a), np.asarray(b)
    if a.shape != b.shape:
        return False
    bound = FORCE_TOL * max(1.0, float(np.max(np.abs(a), initial=0.0))) if scale else TOL
    return bool(np.max(np.abs(a - b), initial=0.0) <= bound)


def lockstep(model, state, inputs):
    """Run both steps; assert agreement after every step; return the compiled reports."""
    engine = Engine(model)
    a = b = state
    reports = []
    for k, inp in enumerate(inputs):
        a, ra = step(model, a, inp)
        b, rb = engine.step(b, inp)
        where = f"step {k}"
        assert (ra.rows, ra.contacts, ra.iterations, ra.solver, ra.substeps) == (
            rb.rows,
            rb.contacts,
            rb.iterations,
            rb.solver,
            rb.substeps,
        ), where
        assert (a.time, a.step) == (b.time, b.step), where
        assert np.array_equal(a.joint_yielded, b.joint_yielded), where
        assert np.array_equal(a.warm_key, b.warm_key), where
        for name in STATE:
            assert close(getattr(a, name), getattr(b, name)), (where, name)
        for name in FORCES:
            assert close(getattr(a, name), getattr(b, name), scale=True), (where, name)
        for name in ("grip_force", "grip_torque", "touch_force", "pin_force", "pin_torque"):
            assert close(getattr(ra, name), getattr(rb, name), scale=True), (where, name)
        assert np.array_equal(ra.pin_slip, rb.pin_slip), where
        reports.append(rb)
    return reports


def test_creep_rig_matches_the_numpy_step():
    h = 0.02
    model = build_model(one_bone(h, KF, DF, DD, INERTIA))
    loaded = StepInput(body_torque=np.array([[0.0, 0.0, TAU]]))
    inputs = [loaded if k < round(T_LOAD / h) else None for k in range(round(T_END / h))]
    reports = lockstep(model, initial_state(model), inputs)
    assert {r.solver for r in reports} == {"direct"}


@pytest.mark.parametrize("h", [0.02, 0.005])
def test_fast_step_reproduces_the_exact_discrete_recursion(h):
    model = build_model(one_bone(h, KF, DF, DD, INERTIA))
    engine = Engine(model)
    state = initial_state(model)
    loaded = StepInput(body_torque=np.array([[0.0, 0.0, TAU]]))
    angles = []
    for k in range(round(T_END / h)):
        state, _ = engine.step(state, loaded if k < round(T_LOAD / h) else None)
        angles.append(joint_rotations(model, state)[0, 2])
    # measured 6.1e-16 (h = 20 ms), 4.0e-15 rad (5 ms); 1e-12: rounding headroom
    assert np.max(np.abs(np.array(angles) - recursion(h))) < 1e-12


def test_ten_link_chain_with_yield_grip_and_projection_matches():
    # h = 5 ms and a grip near its force limit: joints yield and re-anchor, the direct
    # solve's active set pins grip rows at their limits, the joint projection engages.
    h = 0.005
    model = build_model(chain(10, h, rheo=rheology(5.0, 0.5, 2.0, 0.8)))
    state = initial_state(model)
    tip = model.bone_tail0[9]
    still = Pointer(tip, quat.IDENTITY.copy(), np.zeros(3), np.zeros(3))
    grip = make_coupling(
        state,
        still,
        9,
        tip,
        stiffness=500.0,
        damping=5.0,
        rot_stiffness=2.0,
        rot_damping=0.05,
        force_limit=8.0,
        torque_limit=0.5,
    )
    velocity = np.array([0.0, 0.3, 0.1])
    inputs = []
    for k in range(300):
        t = min((k + 1) * h, 1.0)
        ptr = Pointer(tip + t * velocity, quat.IDENTITY.copy(), velocity, np.zeros(3))
        inputs.append(StepInput(pointer=ptr, coupling=grip))
    reports = lockstep(model, state, inputs)
    assert {r.solver for r in reports} == {"direct"}
    assert sum(np.abs(r.grip_force).max() == 8.0 for r in reports) > 100


def test_pinned_chain_with_a_grip_and_a_slipping_pin_matches():
    # a free 10-link chain: its root pinned whole, link 5 at its tail with a force limit
    # it reaches (it slips), the tip gripped and pulled up: pin rows after the grip's,
    # iterated by the hybrid solve in both steps
    h = 0.005
    model = build_model(chain(10, h, root_mode="free", rheo=rheology(5.0, 0.5, 2.0, 0.8)))
    state = initial_state(model)
    mid = model.bone_tail0[5] - model.body_pos0[5]
    pins = (make_pin(state, 0, orient=True), make_pin(state, 5, mid, force_limit=3.0))
    tip = model.bone_tail0[9]
    still = Pointer(tip, quat.IDENTITY.copy(), np.zeros(3), np.zeros(3))
    grip = make_coupling(
        state, still, 9, tip, stiffness=500.0, damping=5.0, rot_stiffness=2.0,
        rot_damping=0.05, force_limit=8.0, torque_limit=0.5,
    )  # fmt: skip
    up = np.array([0.0, 0.3, 0.1])
    inputs = []
    for k in range(200):
        ptr = Pointer(tip + (k + 1) * h * up, quat.IDENTITY.copy(), up, np.zeros(3))
        inputs.append(StepInput(pointer=ptr, coupling=grip, pins=pins))
    reports = lockstep(model, state, inputs)
    assert {r.solver for r in reports} == {"hybrid"}
    assert sum(r.pin_slip[1] for r in reports) > 50
    assert not any(r.pin_slip[0] for r in reports)


@pytest.mark.parametrize("root_mode", ["fixed", "free", "ball"])
def test_chains_solved_directly_match(root_mode):
    rng = np.random.default_rng(7)
    n = 6
    spec = chain(
        n,
        0.01,
        root_mode=root_mode,
        lengths=rng.uniform(0.05, 0.3, n),
        rheo=rheology(2.0, 0.5, 3.0),
    )
    model = build_model(spec)
    state = replace(initial_state(model), body_omega=rng.normal(size=(n, 3)))
    reports = lockstep(model, state, [None] * 60)
    assert {r.solver for r in reports} == {"direct"}


def test_tumbling_chain_with_joint_projection_matches(monkeypatch):
    # A free chain spinning at ~10 rad/s at h = 10 ms opens joint gaps above the projection's
    # trigger (0.2 mm at 10 ms; 44 of its 50 steps): the projection (post-stabilisation)
    # engages in both implementations.
    projected = []

    def counting(model, pos, q, *args, **kwargs):
        projected.append(joint_gaps(model, pos, q).max() > projection_tol(model.options.h))
        return project_joints(model, pos, q, *args, **kwargs)

    monkeypatch.setattr("solver.pipeline.project_joints", counting)
    spec = chain(4, 0.01, root_mode="free", gravity=(0, 0, 0), lengths=[0.3, 0.1, 0.4, 0.2])
    model = build_model(spec)
    omega = np.random.default_rng(0).normal(scale=6.0, size=(4, 3))
    lockstep(model, replace(initial_state(model), body_omega=omega), [None] * 50)
    assert sum(projected) >= 10


def doll_inputs(model, steps: int) -> tuple:
    """Push + grip for the first half (puppetcli.bench.stages's scene), then a free-mode
    pointer sphere pressing down on the left forearm."""
    state, inputs = scene_inputs(model, steps // 2)
    b = model.bone_names.index("forearm_l")
    mid = 0.5 * (model.bone_head0[b] + model.bone_tail0[b])
    top = bone_points(model, state, mid[None], bones=np.array([b]))[0] + [0.0, 0.05, 0.0]
    down = np.array([0.0, -0.4, 0.0])
    h = model.options.h
    for k in range(steps - steps // 2):
        pos = top + (k + 1) * h * down
        inputs.append(
            StepInput(pointer=Pointer(pos, quat.IDENTITY.copy(), down, np.zeros(3), radius=0.02))
        )
    return state, inputs


# The trigger as documented (stabilize's docstring, docs/integrators.md): 0.1 mm up to 5 ms,
# 0.1 mm × h/5 ms above: 0.2 mm at 10 ms, 0.4 mm at 20 ms.
TRIGGERS = {0.001: 1e-4, 0.005: 1e-4, 0.01: 2e-4, 0.02: 4e-4, 0.05: 1e-3, 0.25: 5e-3}


def test_the_projection_trigger_is_the_documented_one():
    for h, trigger in TRIGGERS.items():
        assert projection_tol(h) == pytest.approx(trigger, rel=1e-12)


@pytest.mark.parametrize(
    ("integrator", "h", "spin", "trigger"),
    [("euler", 0.01, 3.0, TRIGGERS[0.01]), ("bdf2", 0.02, 6.0, TRIGGERS[0.02])],
)
def test_gaps_below_a_large_steps_trigger_are_left_to_the_rows(integrator, h, spin, trigger):
    """Above 5 ms the projection's trigger grows with the step (stabilize.projection_tol):
    a tumbling chain's joints open past the 0.1 mm that holds up to 5 ms and are left to the
    rows' drift correction below the step's trigger, alike in both steps (under bdf2 the
    trigger is the step's, not its stage's γ = 2h/3: gaps between the two occur here)."""
    spec = chain(4, h, root_mode="free", gravity=(0, 0, 0), lengths=[0.3, 0.1, 0.4, 0.2])
    model = build_model(spec).with_options(integrator=integrator)
    omega = np.random.default_rng(0).normal(scale=spin, size=(4, 3))
    state = replace(initial_state(model), body_omega=omega)
    lockstep(model, state, [None] * 50)
    engine, worst = Engine(model), 0.0
    for _ in range(50):
        state, _ = engine.step(state)
        worst = max(worst, joint_gaps(model, state.body_pos, state.body_quat).max())
    # measured 1.81e-4 m (euler, 10 ms) and 3.88e-4 m (bdf2, 20 ms)
    assert 1e-4 < worst <= trigger


@pytest.mark.parametrize("method", ["auto", "pgs"])
def test_doll_with_contacts_push_grip_and_touch_matches(method):
    model = build_model(load_rig(DOLL)).with_options(h=0.001, method=method)
    assert supports(pack(model))
    state, inputs = doll_inputs(model, 500)
    reports = lockstep(model, state, inputs)
    assert {r.solver for r in reports} == {"hybrid" if method == "auto" else "pgs"}
    assert min(r.contacts for r in reports) > 0
    assert max(np.abs(r.grip_force).max() for r in reports[:250]) > 1.0
    assert max(np.abs(r.touch_force).max() for r in reports[250:]) > 1.0


def test_steps_without_input_between_grips_match():
    """A step without input reuses one packed input with flags of its own
    (fast._input_arrays): after a gripped step it must let go, and the grip after it take
    hold again, as the numpy step does."""
    model = build_model(load_rig(DOLL)).with_options(h=0.001)
    state, grips = scene_inputs(model, 60)
    inputs = [None] * 5 + grips[:20] + [None] * 10 + grips[30:50] + [None] * 10
    reports = lockstep(model, state, inputs)
    assert max(np.abs(r.grip_force).max() for r in reports[5:25]) > 1.0
    assert not any(r.grip_force.any() for r in reports[25:35] + reports[55:])
    assert all(r.grip_force.any() for r in reports[35:55])


def lying_chain(links: int = 30, iterations: int = 100):
    """(model, state): a free chain of balls lying on a slab (a dynamic prop) that rests
    on the ground: a resting contact each between two moving bodies, iterated (the
    slab's four contacts with the ground are leaf contacts: solver.solve.hybrid)."""
    spec = chain(links, 0.001, root_mode="free", ground=0.94, collide=True, shape="sphere")
    slab = PropSpec("slab", ShapeSpec("box", half_extents=(0.1 * links / 2 + 0.1, 0.02, 0.1)),
                    np.array([0.1 * links / 2, 0.96, 0.0]), quat.IDENTITY.copy(), dynamic=True,
                    mass=50.0)  # fmt: skip
    model = build_model(replace(spec, props=(slab,))).with_options(iterations=iterations)
    return model, initial_state(model)


def test_more_iterated_rows_than_the_scratch_holds_matches(monkeypatch):
    # 30 contacts: 90 rows in the hybrid's Schur complement, more than the step's scratch
    # holds (solver.solve.hybrid_kernel.NU_CAP), so the compiled solve makes a matrix of its own.
    # 100 sweeps converge, so the two implementations agree to rounding.
    sizes = []  # rows the numpy hybrid iterates, step by step
    dense_pgs = hybrid.dense_pgs

    def counted(q, c, *args):
        sizes.append(len(c))
        return dense_pgs(q, c, *args)

    monkeypatch.setattr(hybrid, "dense_pgs", counted)
    model, state = lying_chain()
    reports = lockstep(model, state, [None] * 40)
    assert {r.solver for r in reports} == {"hybrid"}
    # the first step solves twice (its slab contacts, then the balls' woken ones with them)
    assert min(sizes[1:]) > NU_CAP and len(sizes) == 41


def test_chain_tumbling_onto_a_frictionless_ground_matches(monkeypatch):
    # Frictionless balls: each one's contact with the ground is a leaf contact of the
    # compiled forest (solver.solve.hybrid), the contacts between balls and the limits
    # are iterated.  The chain starts 5 mm into the ground, thrown up and spinning: the
    # exact solve would pull on the ground contacts of balls leaving it, which both
    # solves then hold at λ = 0; then it lands and tumbles on the ground.
    pinned = []  # per numpy round: a leaf contact held at λ = 0
    round_ = hybrid._round

    def watched(rows, q, c, lam0, exact, it, pinned_lam, *args):
        pinned.append(bool((hybrid.leaf_contacts(rows) & ~np.isnan(pinned_lam)).any()))
        return round_(rows, q, c, lam0, exact, it, pinned_lam, *args)

    monkeypatch.setattr(hybrid, "_round", watched)
    spec = chain(4, 0.005, root_mode="free", lengths=[0.12, 0.08, 0.15, 0.1], radius=0.03,
                 shape="sphere", collide=True, ground=0.975,
                 limits=LimitSpec(swing=np.radians(20.0), twist=(-0.1, 0.1)))  # fmt: skip
    spec = replace(spec, ground=replace(spec.ground, friction=0.0), bone_friction=0.0)
    model = build_model(spec)
    rng = np.random.default_rng(1)
    state = replace(initial_state(model), body_vel=np.tile([0.0, 2.0, 0.0], (4, 1)),
                    body_omega=rng.normal(scale=2.0, size=(4, 3)))  # fmt: skip
    reports = lockstep(model, state, [None] * 120)
    assert max(r.contacts for r in reports) >= 4
    assert sum(pinned) > 0  # measured: 2 of the numpy solve's 131 rounds


def test_substepped_rope_matches():
    # The light rope at h = 5 ms takes two substeps once its tension builds up; both
    # implementations choose the same count (the same criterion) and the same states.
    model = build_model(chain(40, 0.005, link=0.02, radius=0.005, masses=[0.02] * 40))
    reports = lockstep(model, initial_state(model), [None] * 60)
    assert {r.substeps for r in reports} >= {1, 2}


def test_monitor_failures_raise_the_numpy_steps_error():
    model = build_model(chain(3, 0.01)).with_options(max_speed=0.2)
    engine = Engine(model)
    state = initial_state(model)
    with pytest.raises(SimulationError) as expected:
        for _ in range(100):
            state, _ = step(model, state)
    state = initial_state(model)
    with pytest.raises(SimulationError) as got:
        for _ in range(100):
            state, _ = engine.step(state)
    assert str(got.value) == str(expected.value)
    assert (got.value.step, got.value.bone) == (expected.value.step, expected.value.bone)


def test_forced_direct_solver_on_contacts_raises_the_numpy_steps_error():
    spec = chain(3, 0.01, collide=True, ground=0.99, method="direct")
    model = build_model(spec)
    engine = Engine(model)
    with pytest.raises(SimulationError) as expected:
        state = initial_state(model)
        for _ in range(50):
            state, _ = step(model, state)
    with pytest.raises(SimulationError) as got:
        state = initial_state(model)
        for _ in range(50):
            state, _ = engine.step(state)
    assert str(got.value) == str(expected.value)


LOWER, UPPER = (0.10, 0.04, 0.08), (0.06, 0.03, 0.05)  # the stacked boxes' half extents


def box_stack(turn: float) -> RigSpec:
    """A box on the ground and a smaller one dropped on it from 1 cm, turned by ``turn``
    about the vertical and tilted 0.05 rad (it lands on a corner and settles face down);
    a still capsule bone, free, off to the side."""
    root = BoneSpec("root", None, np.array([0.5, 0.05, 0.0]), np.array([0.7, 0.05, 0.0]),
                    ShapeSpec("capsule", radius=0.05), 1.0)  # fmt: skip
    tilt = quat.mul(quat.exp(np.array([0.0, turn, 0.0])), quat.exp(np.array([0.05, 0.0, 0.0])))
    lower = np.array([0.0, LOWER[1], 0.0])
    upper = np.array([0.01, 2 * LOWER[1] + UPPER[1] + 0.01, 0.0])
    props = (
        PropSpec("lower", ShapeSpec("box", half_extents=LOWER), lower, quat.IDENTITY.copy(),
                 dynamic=True, mass=2.0),
        PropSpec("upper", ShapeSpec("box", half_extents=UPPER), upper, tilt, dynamic=True),
    )  # fmt: skip
    solver = replace(RigSpec("s", (root,)).solver, contact_slop=0.0)
    return RigSpec("stack", (root,), root_mode="free", ground=GroundSpec(), props=props,
                   solver=solver)  # fmt: skip


def test_the_reference_method_runs_on_numpy():
    reference = build_model(chain(3, 0.01)).with_options(method="reference")
    assert not supports(pack(reference))
    assert supports(pack(build_model(chain(3, 0.01))))
    state = initial_state(reference)
    a, ra = step(reference, state)
    b, rb = Engine(reference).step(state)  # delegates to the numpy step
    assert np.array_equal(a.body_pos, b.body_pos) and ra.solver == rb.solver


@pytest.mark.parametrize("turn", [0.0, 0.4])
def test_a_box_dropped_on_a_box_matches_and_comes_to_rest_on_it(turn, monkeypatch):
    """Box–box contacts in the compiled step (solver.collide.boxbox_kernel). Each step of
    the numpy run, taken by the compiled stepper from the same state, agrees with it (a
    15-sweep PGS on four redundant corners amplifies rounding from step to step, so two
    free runs part by ~1e-5 m over 200 steps; each step stays within TOL: measured
    7.4e-11), the kernel taking every step itself, also those in which the upper box,
    settling, presses on the lower one asleep (the forest takes the sleeper as a free
    root: direct_kernel.forest_sequence); the run ends with the upper box at rest face down
    on the lower one, its centre at 2·h_lower + h_upper (no contact slop: measured
    −5.8e-8 m, the regularisation's give under its weight)."""
    model = build_model(box_stack(turn)).with_options(h=0.005)
    assert supports(pack(model))
    handed = []
    original = sim_module.fast_step

    def counted(*args):
        handed.append(args[1].step)
        return original(*args)

    monkeypatch.setattr(sim_module, "fast_step", counted)
    a, stepper, boxbox, on_sleeper = initial_state(model), Engine(model).stepper(), 0, 0
    lower, upper = model.body_names.index("lower"), model.body_names.index("upper")
    for k in range(200):
        on_sleeper += bool(len(a.body_asleep)) and a.body_asleep[lower] > a.body_asleep[upper]
        stepper.load(a)
        stepper.advance()
        a, ra = step(model, a)
        b, rb = stepper.state, stepper.report
        assert (ra.rows, ra.contacts, ra.iterations, ra.solver) == (
            rb.rows, rb.contacts, rb.iterations, rb.solver,
        ), k  # fmt: skip
        for name in STATE:
            assert close(getattr(a, name), getattr(b, name)), (k, name)
        boxbox += ra.contacts >= 8
    assert handed == [] and boxbox > 150 and on_sleeper > 0  # measured: 196 and 8 steps
    height = a.body_pos[upper, 1] - (2 * LOWER[1] + UPPER[1])
    assert abs(height) < 2e-7, height
    assert np.abs(a.body_vel).max() < 1e-5  # measured 2.6e-6 (both turns)
