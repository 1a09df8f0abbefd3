"""Every solver mode's step satisfies the row problem's optimality (KKT) conditions.

The oracle is the problem's statement (solver/rows/table.py), checked here with dense
matrices this module builds itself, on whole steps of the public engine (numpy and
compiled), for every solver method, on scenes with friction, joint limits, plastic joint
rows and a grip at and below its force limit:

- Newton over the step: each movable body's m(v⁺ − v_free) and I_w(ω⁺ − ω) equal
  h·Jᵀλ, with v_free = v + h g (the step's gravity) and I_w = R I Rᵀ from the model's
  body-frame inertia at the step's start;
- the row residual r = J v⁺ + C λ + β: within the bounds lo ≤ λ ≤ hi (friction rows
  ±μ λ_normal: the friction pyramid), r = 0 where λ is inside them, r ≥ 0 at the lower
  bound and r ≤ 0 at the upper one.

v⁺ is the solved velocity: the linear one the step keeps, and the angular one recovered
from the angular momentum the step carries (ω⁺ = I_w(q)⁻¹ I_w(q⁺) ω_next, the
integrator's documented momentum form).  λ is the step's force per row, read from the
state's warm-start table by row key; the rows themselves (J, C, β, bounds) are the
step's input, rebuilt with ``build_rows`` (their Jacobians are checked against finite
differences in test_jacobians.py), with the regularisation C = ε·h J M⁻¹Jᵀ of hard rows
computed here.  A 1.5× wide friction cone, a wrong grip bias or a 1 % error in gravity,
mass or compliance breaks these conditions.
"""

from __future__ import annotations

import functools
from dataclasses import replace

import numpy as np
import pytest
from rigbuild import chain, rheology
from scipy.spatial.transform import Rotation
from test_solvers import contact_scene

from solver.engine import Engine
from solver.model import build_model
from solver.rows.build import build_rows
from solver.rows.grip import Pointer, make_coupling
from solver.rows.table import KIND_CONTACT, KIND_FRICTION, KIND_GRIP, KIND_LIMIT
from solver.state import StepInput, initial_state

IDENTITY = np.array([1.0, 0.0, 0.0, 0.0])


def rotations(q: np.ndarray) -> np.ndarray:
    """(n,3,3) rotation matrices of (n,4) (w,x,y,z) quaternions, by scipy."""
    return Rotation.from_quat(q, scalar_first=True).as_matrix()


def grip_input(model, state, limit: float, pull=(0.05, 0.3, 0.0)) -> StepInput:
    """A grip on the last body, its pointer moved ``pull`` (m) and turned 0.4 rad."""
    b = model.nbody - 1
    centre = state.body_pos[b]
    here = Pointer(centre, IDENTITY, np.zeros(3), np.zeros(3))
    coupling = make_coupling(state, here, b, centre, stiffness=2000.0, damping=40.0,
                             rot_stiffness=50.0, rot_damping=2.0, force_limit=limit,
                             torque_limit=limit)  # fmt: skip
    turn = Rotation.from_rotvec([0.0, 0.4, 0.2]).as_quat(scalar_first=True)
    ptr = Pointer(centre + np.asarray(pull), turn, np.array([0.1, 0.0, 0.0]), np.zeros(3))
    return StepInput(pointer=ptr, coupling=coupling)


@functools.cache
def free_chain():
    """A hanging plastic chain of balls without contacts or limits: every row two-sided.
    Balls: their isotropic inertia makes ω⁺ = ω_next whatever the anchor projection
    after the step (solver/advance/stabilize.py) did to the orientations."""
    model = build_model(chain(4, 0.005, rheo=rheology(2.0, 0.2, 8.0), shape="sphere", radius=0.03))
    state = initial_state(model)
    rng = np.random.default_rng(7)
    spin = rng.normal(scale=1.0, size=(model.nbody, 3))
    spin[model.body_inv_mass == 0.0] = 0.0  # the fixed root stays still
    state = replace(state, body_omega=spin)
    return model, state


def solved_step(model, state, inp, engine: str, method: str):
    """(model as run, state after one step) of the public engine, one substep, no sleep."""
    run = model.with_options(engine=engine, method=method, iterations=4000, sleep=False,
                             max_substeps=1)  # fmt: skip
    new, report = Engine(run).step(state, inp)
    assert report.substeps == 1
    return run, new


def world_inertia(model, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(I_w, I_w⁻¹) (nb,3,3) at orientations q from the body-frame inertia."""
    rot = rotations(q)
    inertia = rot @ model.body_inertia @ np.swapaxes(rot, 1, 2)
    inverse = rot @ model.body_inv_inertia @ np.swapaxes(rot, 1, 2)
    return inertia, inverse


def dense_jacobian(rows, nbody: int) -> np.ndarray:
    """J (n, 6 nbody): each row's two blocks at its bodies' columns, the world dropped."""
    jac = np.zeros((len(rows), 6 * nbody))
    for i in range(len(rows)):
        for body, block in ((rows.body_a[i], rows.jac_a[i]), (rows.body_b[i], rows.jac_b[i])):
            if body >= 0:
                jac[i, 6 * body : 6 * body + 6] += block
    return jac


def kkt_velocities(model, state, new) -> np.ndarray:
    """(nb,6) the solved velocities of the step state → new: the linear ones it keeps, the
    angular ones from the momentum it carries, ω⁺ = I_w(q)⁻¹ I_w(q⁺) ω_next."""
    _, inverse = world_inertia(model, state.body_quat)
    inertia_next, _ = world_inertia(model, new.body_quat)
    omega = np.einsum("nij,njk,nk->ni", inverse, inertia_next, new.body_omega)
    vel = np.concatenate((new.body_vel, omega), axis=1)
    vel[model.body_inv_mass == 0.0] = 0.0
    return vel


def kkt(model, state, inp, new):
    """(rows, λ, r, Newton's residual (nb,6), force scale) of the step state → new."""
    h = model.options.h
    nb = model.nbody
    movable = model.body_inv_mass > 0.0
    vel_free = np.zeros((nb, 6))
    vel_free[:, :3] = state.body_vel + h * np.where(movable[:, None], model.options.gravity, 0.0)
    vel_free[:, 3:] = state.body_omega
    rows, _, _ = build_rows(model, state, rotations(state.body_quat), vel_free, inp)
    keys = new.warm_key
    at = np.searchsorted(keys, rows.key)
    assert np.array_equal(keys[np.minimum(at, len(keys) - 1)], rows.key)  # one λ per row
    assert len(keys) == len(rows)
    lam = new.warm_lam[at]

    vel = kkt_velocities(model, state, new)
    inertia, inverse = world_inertia(model, state.body_quat)

    jac = dense_jacobian(rows, nb)
    minv = np.zeros((6 * nb, 6 * nb))
    mass = np.zeros((6 * nb, 6 * nb))
    for b in np.flatnonzero(movable):
        s = slice(6 * b, 6 * b + 6)
        minv[s, s][:3, :3] = np.eye(3) * model.body_inv_mass[b]
        minv[s, s][3:, 3:] = inverse[b]
        mass[s, s][:3, :3] = np.eye(3) / model.body_inv_mass[b]
        mass[s, s][3:, 3:] = inertia[b]
    impulse = h * jac.T @ lam
    newton = (mass @ (vel - vel_free).reshape(-1) - impulse).reshape(nb, 6)
    newton[~movable] = 0.0
    diag = h * np.einsum("ij,jk,ik->i", jac, minv, jac)
    comp = np.where(rows.comp > 0.0, rows.comp, model.options.regularization * diag)
    r = jac @ vel.reshape(-1) + comp * lam + rows.bias
    scale = max(1.0, np.abs(impulse).max() / h)
    return rows, lam, r, newton, scale, diag + comp


def bounds(rows, lam) -> tuple[np.ndarray, np.ndarray]:
    """Each row's bounds, friction rows' from their normal row's force."""
    lo, hi = rows.lo.copy(), rows.hi.copy()
    f = rows.fric_of >= 0
    hi[f] = rows.mu[f] * lam[rows.fric_of[f]]
    lo[f] = -hi[f]
    return lo, hi


def natural_residual(lam, r, lo, hi, d) -> np.ndarray:
    """|λ − clip(λ − r/d, lo, hi)|·d (N): 0 exactly at a solution of the mixed LCP
    (interior rows r = 0, rows at lo r ≥ 0, rows at hi r ≤ 0)."""
    return np.abs(lam - np.clip(lam - r / d, lo, hi)) * d


CONTACT_MODES = [
    (engine, method) for engine in ("numpy", "compiled") for method in ("pgs", "hybrid", "auto")
]


@pytest.mark.parametrize("limit", [0.3, 1e6])
@pytest.mark.parametrize(("engine", "method"), CONTACT_MODES)
@pytest.mark.parametrize("seed", [1, 5])
def test_contact_scene_step_is_a_solution_of_its_lcp(seed, engine, method, limit):
    model, state = contact_scene(seed)
    inp = grip_input(model, state, limit)
    run, new = solved_step(model, state, inp, engine, method)
    rows, lam, r, newton, scale, d = kkt(run, state, inp, new)
    kinds = set(rows.kind.tolist())
    assert {KIND_CONTACT, KIND_FRICTION, KIND_LIMIT, KIND_GRIP} <= kinds  # every kind is here
    lo, hi = bounds(rows, lam)
    fric = rows.fric_of >= 0
    # the friction pyramid and every other bound, at rounding
    assert np.all(lam >= lo - 1e-9 * scale) and np.all(lam <= hi + 1e-9 * scale)
    assert np.all(np.abs(lam[fric]) <= rows.mu[fric] * lam[rows.fric_of[fric]] + 1e-9 * scale)
    # measured (seeds 1, 5; both limits; both engines; every method; relative to the
    # largest row force): Newton ≤ 2.4e-17, the natural residual ≤ 7.1e-14 (PGS's 4,000
    # sweeps converge to rounding here, as the hybrid's and the direct solves do)
    assert np.abs(newton).max() < 1e-16 * scale
    assert natural_residual(lam, r, lo, hi, d).max() < 3e-13 * scale
    if limit < 100.0:  # the cone check has teeth: some contact slides, its friction at μλ_n
        assert np.isclose(np.abs(lam[fric]), hi[fric], rtol=1e-9).any()
    grip = rows.kind == KIND_GRIP
    assert np.isclose(np.abs(lam[grip]), limit).any() == (limit < 100.0)  # saturated or not


@pytest.mark.parametrize("limit", [0.5, 1e6])
@pytest.mark.parametrize("engine", ["numpy", "compiled"])
@pytest.mark.parametrize("method", ["direct", "auto", "hybrid"])
def test_two_sided_scene_step_solves_its_rows_exactly(method, engine, limit):
    model, state = free_chain()
    inp = grip_input(model, state, limit, pull=(0.1, 0.2, -0.05))
    run, new = solved_step(model, state, inp, engine, method)
    rows, lam, r, newton, scale, d = kkt(run, state, inp, new)
    lo, hi = bounds(rows, lam)
    assert np.all(lam >= lo - 1e-12 * scale) and np.all(lam <= hi + 1e-12 * scale)
    assert np.abs(newton).max() < 1e-17 * scale  # measured 1.9e-18 (relative, as above)
    assert natural_residual(lam, r, lo, hi, d).max() < 1e-15 * scale  # measured 1.7e-16
    grip = rows.kind == KIND_GRIP
    assert np.isclose(np.abs(lam[grip]), limit).any() == (limit < 100.0)


SCENES = {"contacts": lambda: contact_scene(1), "chain": free_chain}


@pytest.mark.parametrize("scene", sorted(SCENES))
@pytest.mark.parametrize("engine", ["numpy", "compiled"])
@pytest.mark.parametrize("method", ["pgs", "hybrid", "auto"])
def test_an_unsaturated_grip_is_a_backward_euler_spring_damper(scene, engine, method):
    # The coupling's force on the bone is the Voigt element's after the step (digest §4;
    # the spring sees the deflection at the step's end): f = −K (e + h w) − D (w − u),
    # e the grip point's offset from the pointer's at the step's start, w its solved
    # velocity, u the pointer's; and the same for the rotation with e_rot the rotation
    # vector of R_bone · R_target⁻¹ (world frame) and u the pointer's ω.  Everything here
    # from the state, the pointer and the gains, by scipy.
    model, state = SCENES[scene]()
    inp = grip_input(model, state, 1e6)
    run, new = solved_step(model, state, inp, engine, method)
    rows, lam, *_ = kkt(run, state, inp, new)
    c, ptr, h = inp.coupling, inp.pointer, run.options.h
    b = c.body
    body = Rotation.from_quat(state.body_quat[b], scalar_first=True)
    turn = Rotation.from_quat(ptr.quat, scalar_first=True)
    target_rot = turn * Rotation.from_quat(c.rest, scalar_first=True)
    r_b = body.apply(c.anchor)
    e = state.body_pos[b] + r_b - (ptr.pos + turn.apply(c.offset))
    u = ptr.vel + np.cross(ptr.omega, turn.apply(c.offset))
    omega_next = kkt_velocities(run, state, new)[b, 3:]
    w = new.body_vel[b] + np.cross(omega_next, r_b)
    force = -c.stiffness * (e + h * w) - c.damping * (w - u)
    e_rot = (body * target_rot.inv()).as_rotvec()
    torque = -c.rot_stiffness * (e_rot + h * omega_next) - c.rot_damping * (omega_next - ptr.omega)
    grip = lam[rows.kind == KIND_GRIP]
    # measured (every scene, engine and method), relative to the largest component:
    # force 3.4e-16, torque 5.5e-15
    np.testing.assert_allclose(grip[:3], force, rtol=0, atol=2e-15 * np.abs(force).max())
    np.testing.assert_allclose(grip[3:], torque, rtol=0, atol=3e-14 * np.abs(torque).max())
