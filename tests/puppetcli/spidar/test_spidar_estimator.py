"""SPIDAR pose estimation: tracking lag of the device's fixed-iteration Gauss–Newton, the ideal
estimator's quantisation limit, the fixed point, the rotation clamp and the velocity filter."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import lfilter
from scipy.spatial.transform import Rotation

from puppetcli.spidar import (
    EstimatorSettings,
    PoseEstimator,
    counts_from_pose,
    preset,
    structure_matrix,
)

DT = 1e-3
TRANSIENT = 100  # ticks skipped before measuring lag (the motion starts at home anyway)


def rotation_error_deg(q_a: np.ndarray, q_b: np.ndarray) -> np.ndarray:
    """Angle (°) of q_a q_b⁻¹, by scipy (independent of solver.quat)."""
    ra = Rotation.from_quat(q_a, scalar_first=True)
    rb = Rotation.from_quat(q_b, scalar_first=True)
    return np.degrees((ra * rb.inv()).magnitude())


def sinusoid(duration: float = 1.5):
    """±3 cm at 2 Hz along a skew direction, ±30° at 1 Hz about a skew axis, at 1 kHz."""
    t = np.arange(1, round(duration / DT) + 1) * DT
    direction = np.array([1.0, 0.6, -0.8]) / np.linalg.norm([1.0, 0.6, -0.8])
    axis = np.array([0.3, 1.0, 0.5]) / np.linalg.norm([0.3, 1.0, 0.5])
    pos = 0.03 * np.sin(2 * np.pi * 2.0 * t)[:, None] * direction
    angle = np.radians(30.0) * np.sin(2 * np.pi * 1.0 * t)
    q = Rotation.from_rotvec(angle[:, None] * axis).as_quat(scalar_first=True)
    return t, pos, q


def test_home_counts_give_home():
    est = PoseEstimator(preset("SpidarG6X3R"))
    pos, q = est.update(np.zeros(8, dtype=int))
    assert np.array_equal(pos, np.zeros(3))
    assert np.array_equal(q, np.array([1.0, 0.0, 0.0, 0.0]))


@pytest.mark.parametrize("name", ["SpidarG6X3R", "SpidarG6X3L"])
def test_fixed_iteration_estimator_tracks_a_moving_grip(name):
    """Lag = the fixed-iteration estimate's distance from the ideal (converged) estimate
    of the same quantised counts, after the first 0.1 s: quantisation cancels, what is left
    is the lag of 2 damped iterations per tick.  Notes: ≤ 0.05 mm, ≤ 0.25°; asserted
    < 0.1 mm, < 0.5° (measured 0.050 mm, 0.33° on this motion; against the truth 0.051 mm,
    0.32°)."""
    p = preset(name)
    _, pos, q = sinusoid()
    counts = counts_from_pose(p, pos, q)
    fixed = PoseEstimator(p).track(counts)
    ideal = PoseEstimator(p, ideal=True).track(counts)
    lag_mm = np.linalg.norm(fixed.pos - ideal.pos, axis=1)[TRANSIENT:] * 1e3
    lag_deg = rotation_error_deg(fixed.quat, ideal.quat)[TRANSIENT:]
    assert lag_mm.max() < 0.1
    assert lag_deg.max() < 0.5
    assert np.all(fixed.iterations == 2)
    # Against the scripted truth the error is the lag plus the quantisation error.
    truth_mm = np.linalg.norm(fixed.pos - pos, axis=1)[TRANSIENT:] * 1e3
    truth_deg = rotation_error_deg(fixed.quat, q)[TRANSIENT:]
    assert truth_mm.max() < 0.1 + 0.03 and truth_deg.max() < 0.5 + 0.3


def quantisation_bound(p, pos, q) -> np.ndarray:
    """Per-component bound on the least-squares pose error from rounded counts.

    Lengths are off by δl_i with |δl_i| ≤ |κ_i|/2.  Linearised, δl = −A δx, and the
    least-squares pose moves by δx = −A⁺ δl, so |δx_j| ≤ Σ_i |A⁺_ji| |κ_i|/2 (position in m,
    rotation in rad).  Curvature adds O(|δx|²/l) ≈ 1e-9 m, covered by the slack.
    """
    a_pinv = np.linalg.pinv(structure_matrix(p, pos, q))
    return np.abs(a_pinv) @ (np.abs(p.metres_per_count) / 2) * 1.01 + 1e-9


@pytest.mark.parametrize("name", ["SpidarG6X3R", "SpidarG6X4R", "HISpidarG6X"])
def test_ideal_estimator_is_quantisation_limited_on_static_poses(name):
    p = preset(name)
    rng = np.random.default_rng(7)
    for _ in range(20):
        pos = rng.uniform(-0.02, 0.02, 3)
        rotvec = rng.normal(size=3)
        rotvec *= np.radians(rng.uniform(0, 30)) / np.linalg.norm(rotvec)
        q = Rotation.from_rotvec(rotvec).as_quat(scalar_first=True)
        est = PoseEstimator(p, ideal=True)  # cold: from home, up to 3.5 cm and 30° away
        got_pos, got_q = est.update(counts_from_pose(p, pos, q))
        rot_err = (
            Rotation.from_quat(got_q, scalar_first=True)
            * Rotation.from_quat(q, scalar_first=True).inv()
        ).as_rotvec()  # left error: the δθ of the linearisation
        error = np.abs(np.concatenate((got_pos - pos, rot_err)))
        bound = quantisation_bound(p, pos, q)
        assert np.all(error <= bound), (error, bound)


def test_fixed_iteration_estimator_converges_to_the_ideal_pose():
    """The damping changes the steps, not the fixed point: held still, the device's
    estimator reaches the least-squares pose (bias off, so the fixed point is exact)."""
    p = preset("SpidarG6X3R")
    pos = np.array([0.02, -0.015, 0.01])
    q = Rotation.from_euler("xyz", [20, -10, 25], degrees=True).as_quat(scalar_first=True)
    counts = counts_from_pose(p, pos, q)
    ideal_pos, ideal_q = PoseEstimator(p, ideal=True).update(counts)
    fixed = PoseEstimator(p, EstimatorSettings(bias_rate=0.0))
    for _ in range(200):  # notes: ≈ 45 iterations from home to a 1e-9 m step
        got_pos, got_q = fixed.update(counts)
    np.testing.assert_allclose(got_pos, ideal_pos, rtol=0.0, atol=7e-17)  # measured 1.4e-17 m
    assert rotation_error_deg(got_q, ideal_q) < 1.3e-13  # measured 2.6e-14°


def test_rotation_is_clamped_at_ninety_degrees():
    p = preset("SpidarG6X3R")
    q = Rotation.from_euler("y", 100, degrees=True).as_quat(scalar_first=True)
    counts = counts_from_pose(p, np.zeros(3), q, check=False)
    est = PoseEstimator(p)
    for _ in range(300):
        _, got = est.update(counts)
        # measured: never above π/2; 1e-15 for the rounding of scipy's magnitude
        assert Rotation.from_quat(got, scalar_first=True).magnitude() <= np.pi / 2 + 1e-15
    unclamped = PoseEstimator(p, EstimatorSettings(angle_max=None))
    for _ in range(300):
        _, got = unclamped.update(counts)
    assert Rotation.from_quat(got, scalar_first=True).magnitude() > np.radians(99)


def test_velocity_is_the_low_passed_difference_of_the_previous_estimates():
    """v_k = α v_{k−1} + (1 − α)(p_{k−1} − p_{k−2})/dt (one tick late, as Springhead), by
    scipy's lfilter on the estimator's own pose track; ω likewise with scipy rotations."""
    p = preset("SpidarG6X3R")
    _, pos, q = sinusoid(0.5)
    track = PoseEstimator(p).track(counts_from_pose(p, pos, q))
    home = np.array([[1.0, 0.0, 0.0, 0.0]])
    prev_pos = np.vstack((np.zeros((2, 3)), track.pos[:-2]))
    last_pos = np.vstack((np.zeros((1, 3)), track.pos[:-1]))
    raw_v = (last_pos - prev_pos) / DT
    prev_q = Rotation.from_quat(np.vstack((home, home, track.quat[:-2])), scalar_first=True)
    last_q = Rotation.from_quat(np.vstack((home, track.quat[:-1])), scalar_first=True)
    raw_w = (last_q * prev_q.inv()).as_rotvec() / DT
    alpha = 0.8
    expected_v = lfilter([1 - alpha], [1, -alpha], raw_v, axis=0)
    expected_w = lfilter([1 - alpha], [1, -alpha], raw_w, axis=0)
    # measured 0 m/s and 2.0e-14 rad/s
    np.testing.assert_allclose(track.velocity, expected_v, rtol=0.0, atol=1e-13)
    np.testing.assert_allclose(track.angular_velocity, expected_w, rtol=0.0, atol=1e-13)
    # It follows the true motion, late by the predicted delay: the one-pole's α/(1 − α) = 4
    # ticks, plus half a tick for the difference and one tick for running before the update.
    t, _, _ = sinusoid(0.5)
    direction = np.array([1.0, 0.6, -0.8]) / np.linalg.norm([1.0, 0.6, -0.8])
    delay = (alpha / (1 - alpha) + 1.5) * DT
    late_v = 0.03 * 4 * np.pi * np.cos(4 * np.pi * (t - delay))[:, None] * direction
    error = np.linalg.norm(track.velocity - late_v, axis=1)[TRANSIENT:]
    assert error.max() < 0.01  # m/s, of a 0.377 m/s peak (measured 0.0024)


def test_bad_counts_shape_is_a_device_error():
    from puppetcli.spidar import DeviceError

    with pytest.raises(DeviceError, match="expected 8 counts, got shape"):
        PoseEstimator(preset("SpidarG6X3R")).update(np.zeros(6))
