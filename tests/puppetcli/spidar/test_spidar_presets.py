"""SPIDAR presets: tables against the reference notes, counts at home, mirror units, YAML files,
reachability errors."""

from __future__ import annotations

import re

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from puppetcli.spidar import (
    DeviceError,
    check_reachable,
    counts_from_pose,
    lengths_from_counts,
    lengths_from_pose,
    preset,
    preset_from_text,
    preset_from_yaml,
    preset_names,
    preset_to_yaml,
)

IDENTITY = np.array([1.0, 0.0, 0.0, 0.0])
ROUND = 1.4e-16
"""m: rounding of lengths below 0.3 m (the worst measured here is 2.8e-17)."""

# The reference notes' preset table (spidar-and-haptics.md §2): frame half-size (m) before
# the layout rotation, grip radius (m), |m/count|, V/N, t_min, t_max, layout turn about y (°),
# motors whose length per count is negative (notes for G6X3; Springhead sources otherwise).
G6X3 = ((0.060, 0.076, 0.060), 0.0225, 1.66555e-5, 0.3653, 0.3, 20.0, -45, (2, 3, 4, 5))
TABLE = {
    "SpidarG6X3R": G6X3,
    "SpidarG6X3L": G6X3,
    "SpidarG6X4R": ((0.069, 0.095, 0.069), 0.0225, 3.485e-5, 0.08, 0.2, 20.0, 0, (0, 1, 6, 7)),
    "SpidarG6X4L": ((0.069, 0.095, 0.069), 0.0225, 3.485e-5, 0.08, 0.2, 20.0, 0, (0, 1, 6, 7)),
    "HISpidarG6X": ((0.0645, 0.0645, 0.0685), 0.020, 2.924062e-5, 0.12, 1.0, 20.0, 0, (0, 2, 5, 7)),
}


def random_poses(rng: np.random.Generator, count: int, reach: float, angle_deg: float):
    """Grip poses within ±reach m per axis and up to angle_deg about a random axis."""
    pos = rng.uniform(-reach, reach, (count, 3))
    axes = rng.normal(size=(count, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    angles = np.radians(rng.uniform(0.0, angle_deg, count))
    q = Rotation.from_rotvec(axes * angles[:, None]).as_quat(scalar_first=True)
    return pos, q


def lengths_independent(p, pos, q):
    """|m_i − (p + R a_i)| with scipy's rotation matrices (independent of solver.quat)."""
    r = Rotation.from_quat(q, scalar_first=True).as_matrix()
    return np.linalg.norm(p.motor_pos - (pos + p.grip_attach @ r.T), axis=1)


@pytest.mark.parametrize("name", list(TABLE))
def test_preset_matches_the_reference_table(name):
    half, grip, kappa, vpn, t_min, t_max, turn, negative = TABLE[name]
    p = preset(name)
    unturned = Rotation.from_euler("y", -turn, degrees=True).apply(np.array(p.motor_pos))
    np.testing.assert_allclose(np.max(np.abs(unturned), axis=0), np.abs(half), rtol=0, atol=ROUND)
    np.testing.assert_allclose(np.linalg.norm(p.grip_attach, axis=1), grip, rtol=0, atol=ROUND)
    # as the notes round them: measured 3.7e-8 and 8.8e-6 relative
    np.testing.assert_allclose(np.abs(p.metres_per_count), kappa, rtol=1.8e-7)
    assert sorted(np.nonzero(p.metres_per_count < 0)[0]) == list(negative)
    np.testing.assert_allclose(np.abs(p.volts_per_newton), vpn, rtol=4.4e-5)
    assert (p.t_min, p.t_max) == (t_min, t_max)
    assert p.n_strings == 8


def test_g6x3_home_lengths_and_conditioning_match_the_notes():
    """Notes: home string lengths 0.100–0.104 m; the 8×6 Jacobian's condition number ≈ 83."""
    p = preset("SpidarG6X3R")
    assert np.all((p.home_lengths > 0.100) & (p.home_lengths < 0.104))
    d = p.motor_pos - p.grip_attach
    u = d / np.linalg.norm(d, axis=1, keepdims=True)
    a = np.hstack((u, np.cross(p.grip_attach, u)))
    s = np.linalg.svd(a, compute_uv=False)
    assert s[0] / s[-1] == pytest.approx(83, abs=0.5)  # the notes' whole number: 83.27


@pytest.mark.parametrize("name", preset_names())
def test_counts_are_zero_at_home_and_quantise_lengths(name):
    p = preset(name)
    assert np.array_equal(counts_from_pose(p, np.zeros(3), IDENTITY), np.zeros(8, dtype=int))
    pos, q = random_poses(np.random.default_rng(1), 50, 0.02, 25.0)
    counts = counts_from_pose(p, pos, q)
    exact = np.array([lengths_independent(p, pos[k], q[k]) for k in range(len(pos))])
    error = np.abs(lengths_from_counts(p, counts) - exact)
    assert np.all(error <= np.abs(p.metres_per_count) / 2 + ROUND)
    np.testing.assert_allclose(lengths_from_pose(p, pos, q), exact, rtol=0, atol=ROUND)


MIRROR = np.diag([-1.0, 1.0, 1.0])  # x → −x: the device frame seen in a mirror


def mirror_permutation(right, left) -> list[int]:
    """π with m_L[π(i)] = M m_R[i] and a_L[π(i)] = M a_R[i]; fails if there is none."""
    perm = []
    for i in range(right.n_strings):
        m, a = MIRROR @ right.motor_pos[i], MIRROR @ right.grip_attach[i]
        match = [
            j
            for j in range(left.n_strings)
            if np.allclose(left.motor_pos[j], m, rtol=0, atol=ROUND)  # measured: exact
            and np.allclose(left.grip_attach[j], a, rtol=0, atol=ROUND)
            and j not in perm
        ]
        assert match, f"string {i} of {right.name} has no mirror image in {left.name}"
        perm.append(match[0])
    return perm


@pytest.mark.parametrize("unit", ["SpidarG6X3", "SpidarG6X4"])
def test_left_unit_is_the_mirror_image_of_the_right_unit(unit):
    right, left = preset(unit + "R"), preset(unit + "L")
    perm = mirror_permutation(right, left)
    assert sorted(perm) == list(range(8))
    pos, q = random_poses(np.random.default_rng(2), 30, 0.02, 30.0)
    for k in range(len(pos)):
        r = Rotation.from_quat(q[k], scalar_first=True).as_matrix()
        q_mirror = Rotation.from_matrix(MIRROR @ r @ MIRROR).as_quat(scalar_first=True)
        l_right = lengths_independent(right, pos[k], q[k])
        l_left = lengths_independent(left, MIRROR @ pos[k], q_mirror)
        np.testing.assert_allclose(l_left[perm], l_right, rtol=0, atol=ROUND)


def test_preset_lookup_is_case_insensitive_and_suggests_names():
    assert preset("spidarg6x3r").name == "SpidarG6X3R"
    with pytest.raises(DeviceError, match=r"unknown device preset 'SpidarG6X5'.*did you mean"):
        preset("SpidarG6X5")
    with pytest.raises(DeviceError, match="known presets: SpidarG6X3R"):
        preset("phantom")


def test_preset_arrays_are_read_only():
    p = preset("SpidarG6X3R")
    with pytest.raises(ValueError):
        p.motor_pos[0, 0] = 1.0


@pytest.mark.parametrize("name", preset_names())
def test_yaml_round_trip_is_exact(name, tmp_path):
    p = preset(name)
    path = tmp_path / "device.yaml"
    path.write_text(preset_to_yaml(p), encoding="utf-8")
    back = preset_from_yaml(path)
    assert (back.name, back.t_min, back.t_max, back.source) == (p.name, p.t_min, p.t_max, p.source)
    for field in ("motor_pos", "grip_attach", "metres_per_count", "volts_per_newton"):
        assert np.array_equal(getattr(back, field), getattr(p, field)), field


def _text_with(edit) -> str:
    """The G6X3R preset as YAML text with ``edit`` applied to its lines."""
    return "\n".join(edit(preset_to_yaml(preset("SpidarG6X3R")).splitlines())) + "\n"


def _replace(old: str, new: str, count: int = 1):
    return lambda lines: "\n".join(lines).replace(old, new, count).splitlines()


BAD = [
    (_replace("tension: {min: 0.3, max: 20.0}", "tension: {min: 3, max: 2}"),
     r"^dev.yaml:3: tension.max: expected a number > tension.min = 3, got 2$"),
    (_replace("tension: {min: 0.3, max: 20.0}", "tension: {min: 0.3}"),
     r"^dev.yaml:3: tension: expected a value for 'max', got no 'max' key$"),
    (_replace("metres_per_count: 1.66555e-05", "metres_per_count: 0"),
     r"^dev.yaml:7: strings\[0\].metres_per_count: expected a number of magnitude at least "
     r"1e-09 .*, got 0$"),
    (_replace("metres_per_count: 1.66555e-05", "metre_per_count: 1.66555e-05"),
     r"^dev.yaml:7: strings\[0\].metre_per_count: expected one of the keys .*"
     r"\(did you mean 'metres_per_count'\?\)$"),
    (_replace("motor: [-0.08485281374238571, -0.076, 0.0]", "motor: [-0.08, -0.076]"),
     r"^dev.yaml:5: strings\[0\].motor: expected a list of 3 numbers, got a list of 2 items$"),
    (_replace("attach: [0.0, -0.0225, 0.0]", "attach: [0.0, -0.2, 0.0]"),
     r"^dev.yaml:14: strings\[2\].attach: expected a grip point inside the frame at home, got"),
    (_replace("    volts_per_newton: 0.365296803653\n", "", 1),
     r"^dev.yaml:5: strings\[0\]: expected volts_per_newton on every string or on none"),
    (lambda lines: lines[:-4 * 5],
     r"^dev.yaml:5: strings: expected a list of at least 7 strings .*, got a list of 3 items$"),
    (lambda lines: [re.sub(r"attach: \[.*\]", "attach: [0.0, 0.0, 0.0]", x) for x in lines],
     r"^dev.yaml:5: strings: expected strings whose structure matrix at home has rank 6, "
     r"got rank 3$"),
    (lambda lines: [re.sub(r"motor: \[(.*), (.*), (.*)\]", r"motor: [\1, 0.0, \3]", x)
                    for x in lines],
     r"^dev.yaml:5: strings: expected string exits spanning a volume"),
    (lambda lines: ["name: [a]", *lines[1:]],
     r"^dev.yaml:1: name: expected a preset name, got a list of 1 item$"),
]  # fmt: skip


@pytest.mark.parametrize(("edit", "message"), BAD)
def test_bad_preset_yaml_gives_one_precise_line(edit, message):
    with pytest.raises(DeviceError) as caught:
        preset_from_text(_text_with(edit), "dev.yaml")
    text = str(caught.value)
    assert "\n" not in text
    assert re.search(message, text), text


def test_unreadable_preset_file_is_a_device_error(tmp_path):
    with pytest.raises(DeviceError, match="cannot read"):
        preset_from_yaml(tmp_path / "missing.yaml")


def test_unreachable_poses_are_refused_when_recording():
    p = preset("SpidarG6X3R")
    # The top face is at y = 0.076 m; strings 6 and 7 hold the grip 22.5 mm above its centre.
    with pytest.raises(DeviceError, match=r"string 6's attachment is 32.5 mm outside the frame"):
        counts_from_pose(p, np.array([0.0, 0.086, 0.0]), IDENTITY)
    with pytest.raises(DeviceError, match=r"string 6's attachment is 6.5 mm outside the frame"):
        check_reachable(p, np.array([0.0, 0.06, 0.0]), IDENTITY)
    q = Rotation.from_euler("z", 100, degrees=True).as_quat(scalar_first=True)
    with pytest.raises(DeviceError, match=r"grip rotated 100° from home \(expected at most 90°"):
        counts_from_pose(p, np.zeros(3), q)
    track = np.zeros((5, 3))
    track[3, 0] = 0.2
    with pytest.raises(DeviceError, match=r"SpidarG6X3R: pose 3 \(p = \(0.2, 0, 0\) m\)"):
        counts_from_pose(p, track, IDENTITY)
    check_reachable(p, np.zeros((4, 3)), IDENTITY)  # home, four times: fine
