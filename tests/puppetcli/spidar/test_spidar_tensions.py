"""SPIDAR tension distribution: bounds, displayed wrench = Aᵀt, agreement with independent
general-purpose solvers, attenuation beyond capacity, capacity against the notes."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import linprog, lsq_linear, minimize
from scipy.spatial.transform import Rotation

from puppetcli.spidar import (
    DeviceError,
    TensionDistributor,
    TensionWeights,
    capacity,
    motor_volts,
    preset,
    solve_tensions,
    structure_matrix,
)

IDENTITY = np.array([1.0, 0.0, 0.0, 0.0])


def structure_independent(p, pos, q) -> np.ndarray:
    """A (8,6) rows [u_i, r_i × u_i] from scipy rotation matrices and numpy cross products."""
    r = Rotation.from_quat(q, scalar_first=True).as_matrix()
    arm = p.grip_attach @ r.T
    d = p.motor_pos - (pos + arm)
    u = d / np.linalg.norm(d, axis=1, keepdims=True)
    return np.hstack((u, np.cross(arm, u)))


def objective(t, a, wanted, weights: TensionWeights):
    """‖Aᵀt − W_d‖²_Λ + s‖t‖² and its gradient, written from the definition."""
    lam = np.repeat([weights.force, weights.torque], 3)
    r = a.T @ t - wanted
    value = float(r @ (lam * r) + weights.regulariser * t @ t)
    return value, 2 * a @ (lam * r) + 2 * weights.regulariser * t


def reference_tensions(a, wanted, t_min, t_max, weights):
    """The same programme by L-BFGS-B (a quasi-Newton bound-constrained method)."""
    res = minimize(
        objective, np.full(8, t_min), args=(a, wanted, weights), jac=True, method="L-BFGS-B",
        bounds=[(t_min, t_max)] * 8, options={"ftol": 1e-16, "gtol": 1e-12, "maxiter": 10000},
    )  # fmt: skip
    return res.x


def random_cases(count: int, seed: int):
    """(pos, q, wanted wrench) with forces up to 60 N (beyond capacity) and torques to 1 N·m."""
    rng = np.random.default_rng(seed)
    for _ in range(count):
        pos = rng.uniform(-0.02, 0.02, 3)
        q = Rotation.from_rotvec(rng.normal(size=3) * 0.3).as_quat(scalar_first=True)
        scale = rng.choice([1.0, 10.0, 60.0])
        wanted = np.concatenate((rng.normal(size=3) * scale, rng.normal(size=3) * scale / 60))
        yield pos, q, wanted


@pytest.mark.parametrize("name", ["SpidarG6X3R", "SpidarG6X4L", "HISpidarG6X"])
def test_tensions_are_bounded_exact_and_optimal(name):
    p = preset(name)
    weights = TensionWeights()
    for pos, q, wanted in random_cases(40, seed=3):
        a = structure_independent(p, pos, q)
        np.testing.assert_allclose(structure_matrix(p, pos, q), a, rtol=0, atol=1.1e-15)  # 2.2e-16
        got = solve_tensions(a, wanted[:3], wanted[3:], p.t_min, p.t_max, weights)
        assert got.converged
        assert np.all(got.tensions >= p.t_min) and np.all(got.tensions <= p.t_max)
        np.testing.assert_allclose(got.wrench, a.T @ got.tensions, rtol=0, atol=1e-14)  # 0
        ref = reference_tensions(a, wanted, p.t_min, p.t_max, weights)
        # L-BFGS-B's own error: measured 1.7e-7 N
        np.testing.assert_allclose(got.tensions, ref, rtol=0, atol=8.5e-7)
        best = objective(ref, a, wanted, weights)[0]
        assert objective(got.tensions, a, wanted, weights)[0] <= best * (1 + 1e-12) + 1e-12


def test_tensions_match_bounded_least_squares():
    """The programme as bounded least squares, B = [√λ_t U; √λ_r M; √s I], y = [√λ_t f; √λ_r τ; 0],
    by scipy's BVLS: the same tensions to 1e-13 (measured 2.0e-14 N)."""
    p = preset("SpidarG6X3L")
    w = TensionWeights()
    for pos, q, wanted in random_cases(30, seed=4):
        a = structure_independent(p, pos, q)
        scale = np.sqrt(np.repeat([w.force, w.torque], 3))
        b = np.vstack((scale[:, None] * a.T, np.sqrt(w.regulariser) * np.eye(8)))
        y = np.concatenate((scale * wanted, np.zeros(8)))
        ref = lsq_linear(b, y, bounds=(p.t_min, p.t_max), method="bvls", tol=1e-14).x
        got = solve_tensions(a, wanted[:3], wanted[3:], p.t_min, p.t_max, w)
        np.testing.assert_allclose(got.tensions, ref, rtol=0, atol=1e-13)


def test_a_wrench_beyond_capacity_is_attenuated_not_faked():
    p = preset("SpidarG6X3R")
    a = structure_matrix(p, np.zeros(3), IDENTITY)
    wanted = np.array([0.0, 100.0, 0.0])
    got = solve_tensions(a, wanted, np.zeros(3), p.t_min, p.t_max)
    shown = a.T @ got.tensions
    np.testing.assert_array_equal(got.wrench, shown)
    assert np.linalg.norm(shown) < np.linalg.norm(wanted)
    # Not a pure force: the 100 N ask leaves cross-talk torque (so the y component may exceed
    # the pure-force capacity of 29 N), but the strings saturate and the error stays large.
    assert np.linalg.norm(shown - np.concatenate((wanted, np.zeros(3)))) > 40.0
    assert np.isclose(got.tensions.max(), p.t_max)  # the strings are at their limit


def test_qp_attenuation_matches_the_reference_notes():
    """Notes §5.1 (G6X3 at home, default weights): wanted 1 / 5 / 10 N shown as 0.72 / 4.05 /
    8.3 N; a zero wrench leaves every string at t_min with ≈ 0.02 N net force; a wanted
    0.2 N·m is essentially not shown (with s = 0.001, ≈ 0.11 N·m).  The notes do not name the
    axis; y is used, within 2 % (x gives 0.742 / 4.05 / 8.18)."""
    p = preset("SpidarG6X3R")
    a = structure_matrix(p, np.zeros(3), IDENTITY)
    for wanted, shown in ((1.0, 0.72), (5.0, 4.05), (10.0, 8.3)):
        got = solve_tensions(a, np.array([0.0, wanted, 0.0]), np.zeros(3), p.t_min, p.t_max)
        assert got.force[1] == pytest.approx(shown, rel=0.02)  # measured 1.1 % (the axis)
    zero = solve_tensions(a, np.zeros(3), np.zeros(3), p.t_min, p.t_max)
    np.testing.assert_array_equal(zero.tensions, np.full(8, p.t_min))
    # the notes' "≈" values, to their last digit: measured 0.0244 N and 0.1245 N·m
    assert np.linalg.norm(zero.force) == pytest.approx(0.02, abs=0.005)
    torque = np.array([0.2, 0.0, 0.0])
    # measured 3.3e-19 N·m: nothing but rounding
    assert np.linalg.norm(solve_tensions(a, np.zeros(3), torque, 0.3, 20.0).torque) < 1e-16
    soft = solve_tensions(a, np.zeros(3), torque, 0.3, 20.0, TensionWeights(regulariser=0.001))
    assert soft.torque[0] == pytest.approx(0.11, abs=0.02)


def test_capacity_matches_the_notes_and_is_an_lp_optimum():
    """Notes §5.1 (G6X3 at home, 0.3–20 N): ≈ 33 N (+x); 32 N (−x, +z); 29 N (±y); torque
    0.51–0.57 N·m.  Independently: the capacity is feasible (BVLS finds Aᵀt = α e exactly)
    and 1 % more is not (the interior-point LP reports infeasible)."""
    p = preset("SpidarG6X3R")
    cap = capacity(p)
    # the notes' whole newtons (measured 33.33, 32.18, 32.18, 28.84, 28.84)
    assert cap["force"]["+x"] == pytest.approx(33, abs=0.5)
    assert cap["force"]["-x"] == pytest.approx(32, abs=0.5)
    assert cap["force"]["+z"] == pytest.approx(32, abs=0.5)
    assert cap["force"]["+y"] == pytest.approx(29, abs=0.5)
    assert cap["force"]["-y"] == pytest.approx(29, abs=0.5)
    assert all(0.51 <= v <= 0.57 + 1e-3 for v in cap["torque"].values())
    a = structure_independent(p, np.zeros(3), IDENTITY)
    for block, offset in (("force", 0), ("torque", 3)):
        for k, axis in enumerate("xyz"):
            for sign in (1.0, -1.0):
                e = np.zeros(6)
                e[offset + k] = sign
                alpha = cap[block][("+" if sign > 0 else "-") + axis]
                fit = lsq_linear(a.T, alpha * e, bounds=(p.t_min, p.t_max), method="bvls")
                assert np.linalg.norm(a.T @ fit.x - alpha * e) < 1e-12 * alpha  # 1.8e-13
                more = linprog(np.zeros(8), A_eq=a.T, b_eq=1.01 * alpha * e,
                               bounds=[(p.t_min, p.t_max)] * 8, method="highs-ipm")  # fmt: skip
                assert more.status == 2  # infeasible


def test_warm_started_distributor_agrees_with_cold_solves():
    p = preset("SpidarG6X3R")
    dist = TensionDistributor(p)
    t = np.arange(200) * 1e-3
    warm_iterations = cold_iterations = 0
    for tk in t:
        pos = 0.02 * np.array([np.sin(6 * tk), 0.0, np.cos(6 * tk) - 1])
        force = np.array([8 * np.sin(20 * tk), 5.0, -3.0])
        torque = np.array([0.0, 0.1 * np.cos(20 * tk), 0.0])
        warm = dist.display(pos, IDENTITY, force, torque)
        a = structure_matrix(p, pos, IDENTITY)
        cold = solve_tensions(a, force, torque, p.t_min, p.t_max)
        # measured 1.1e-16 N; 2e-15: an ulp of a 10 N tension
        np.testing.assert_allclose(warm.tensions, cold.tensions, rtol=0, atol=2e-15)
        warm_iterations += warm.iterations
        cold_iterations += cold.iterations
    assert warm_iterations < cold_iterations


def test_capped_solver_stays_feasible():
    """A one-pass cap (the device bounds its solver's loop) returns tensions within bounds,
    flagged as not converged, with the displayed wrench still exactly Aᵀt."""
    p = preset("SpidarG6X3R")
    a = structure_matrix(p, np.zeros(3), IDENTITY)
    got = solve_tensions(a, np.array([10.0, -5.0, 3.0]), np.zeros(3), 0.3, 20.0, max_iterations=1)
    assert not got.converged
    assert np.all((got.tensions >= 0.3) & (got.tensions <= 20.0))
    np.testing.assert_array_equal(got.wrench, a.T @ got.tensions)


def test_motor_volts_and_weight_checks():
    p = preset("SpidarG6X4R")
    volts = motor_volts(p, np.array([0.0, 1, 2, 3, 4, 5, 6, 30]))
    signs = np.array([1, 1, -1, -1, -1, -1, 1, 1])  # V/N flipped on motors 2–5
    expected = np.clip([0.0, 1, 2, 3, 4, 5, 6, 30], 0.2, 20.0) * 0.08 * signs
    np.testing.assert_allclose(volts, expected)
    a = structure_matrix(p, np.zeros(3), IDENTITY)
    with pytest.raises(DeviceError, match="regulariser > 0"):
        solve_tensions(a, np.zeros(3), np.zeros(3), 0.2, 20.0, TensionWeights(regulariser=0.0))


def _quadratic(x, q, c):
    """½ xᵀQx − cᵀx and its gradient."""
    return 0.5 * x @ q @ x - c @ x, q @ x - c


def test_box_qp_matches_l_bfgs_b_on_random_problems():
    """The active-set solver on random positive definite QPs with per-variable bounds (wider
    than the device's uniform ones), against L-BFGS-B on ½ xᵀQx − cᵀx."""
    from puppetcli.spidar.boxqp import solve_box_qp

    rng = np.random.default_rng(11)
    for _ in range(50):
        n = int(rng.integers(2, 12))
        m = rng.normal(size=(n, n))
        q = m @ m.T + 0.1 * np.eye(n)
        c = rng.normal(size=n) * 5
        lo = rng.uniform(-2, 0, n)
        hi = lo + rng.uniform(0.1, 3, n)
        got = solve_box_qp(q, c, lo, hi)
        assert got.converged and np.all((got.x >= lo) & (got.x <= hi))
        ref = minimize(
            _quadratic, lo, args=(q, c), jac=True, method="L-BFGS-B",
            bounds=list(zip(lo, hi, strict=True)), options={"ftol": 1e-16, "gtol": 1e-12},
        ).x  # fmt: skip
        np.testing.assert_allclose(got.x, ref, rtol=0, atol=2e-7)  # L-BFGS-B's error: 4.0e-8
