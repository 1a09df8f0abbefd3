"""BVH writer: third-party parsing and FK against keyframe heads, rotations, format, unwrapping.

Independent values: the ``bvh`` package's parse with a scipy-matrix forward
kinematics (test_bvh_fixtures.independent_fk), bvhio's own FK (float32, looser),
scipy's Slerp, and closed-form angle sequences.
"""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp
from test_bvh_fixtures import ORDERS, independent_fk, random_quats, rigid_keys

from puppetcli.bvh.read import bvh_from_text, read_bvh
from puppetcli.bvh.write import bvh_names, bvh_text, resample_keys, write_keys_bvh
from puppetcli.rig.load import load_rig
from puppetcli.rig.skeleton import Skeleton
from puppetcli.run.keyframes import Keyframe, KeyframeSet
from puppetcli.run.runner import Runner, script_model
from puppetcli.script.load import load_script
from solver.model import build_model

with warnings.catch_warnings():  # bvhio imports PyGLM the way PyGLM now deprecates
    warnings.simplefilter("ignore", PendingDeprecationWarning)
    import bvhio

ROOT = Path(__file__).resolve().parents[3]
DOLL = ROOT / "rigs" / "doll.yaml"
CHAIN = ROOT / "rigs" / "chain.yaml"


@pytest.fixture(scope="module")
def doll() -> Skeleton:
    return Skeleton.from_spec(load_rig(DOLL))


def pose_keys(skel: Skeleton, order: str, seed: int) -> list[Keyframe]:
    """Random poses, then poses with every joint near and at gimbal lock in ``order``."""
    rng = np.random.default_rng(seed)
    nb = len(skel.names)
    local = [random_quats(nb, rng) for _ in range(4)]
    for middle in (89.9, -89.9, 90.0, -90.0):
        angles = rng.uniform(-180.0, 180.0, (nb, 3))
        angles[:, 1] = middle
        q = Rotation.from_euler(order, angles, degrees=True).as_quat(scalar_first=True)
        local.append(q)
    root = skel.head0[0] + rng.uniform(-0.5, 0.5, (len(local), 3))
    return rigid_keys(skel, np.array(local), root)


def key_heads(skel: Skeleton, key: Keyframe) -> np.ndarray:
    return np.array([key.bones[n].head for n in skel.names])


@pytest.mark.parametrize("order", ["ZXY", "ZYX", "XYZ"])
@pytest.mark.parametrize("scale", [1.0, 100.0])
@pytest.mark.parametrize("rig", [DOLL, CHAIN])
def test_third_party_fk_puts_joints_at_key_heads(tmp_path, rig, order, scale) -> None:
    skel = Skeleton.from_spec(load_rig(rig))
    keys = pose_keys(skel, order, seed=len(order) + int(scale))
    path = tmp_path / "keys.bvh"
    write_keys_bvh(path, skel, keys, order=order, scale=scale)
    names, parents, positions = independent_fk(path.read_text())
    assert names == list(skel.names)
    assert parents == list(skel.parents)
    assert positions.shape[0] == len(keys)
    for f, key in enumerate(keys):
        err = np.abs(positions[f] / scale - key_heads(skel, key)).max()
        assert err <= 1e-6 * skel.size, f"key {f}: {err:.3g} m"


@pytest.mark.parametrize("order", ["ZXY", "ZYX"])
def test_bvhio_fk_agrees_at_float32_precision(tmp_path, doll, order) -> None:
    keys = pose_keys(doll, order, seed=7)
    path = tmp_path / "keys.bvh"
    write_keys_bvh(path, doll, keys, order=order, scale=100.0)
    root = bvhio.readAsHierarchy(str(path))
    for f, key in enumerate(keys):
        root.loadPose(f)
        found = {j.Name: np.array(j.PositionWorld) / 100.0 for j, _, _ in root.layout()}
        heads = key_heads(doll, key)
        err = max(np.abs(found[n] - heads[i]).max() for i, n in enumerate(doll.names))
        assert err <= 2e-5 * doll.size


@pytest.mark.parametrize("order", ORDERS)
def test_local_rotations_round_trip_through_our_reader(doll, order) -> None:
    keys = pose_keys(doll, order, seed=3)
    bvh = bvh_from_text(bvh_text(doll, keys, order, 1.0, 1 / 30))
    _, rot = bvh.poses()
    for f, key in enumerate(keys):
        want = Rotation.from_quat([key.bones[n].local for n in bvh.names], scalar_first=True)
        got = Rotation.from_quat(rot[f], scalar_first=True)
        # Six decimals of a degree per angle: at most 3 × 0.5e-6° ≈ 2.6e-8 rad per joint.
        assert np.all((want.inv() * got).magnitude() < 3e-8)


def test_simulated_keys_within_the_joint_gaps(tmp_path, doll) -> None:
    """Simulated keys carry small joint gaps (≤ ~1e-4 m mid-motion) that a rigid BVH cannot."""
    spec = load_rig(DOLL)
    plan = load_script(ROOT / "scripts" / "arm_push.yaml", spec)
    result = Runner(script_model(build_model(spec), plan), plan).run()
    keys = list(result.keys)
    path = tmp_path / "arm_push.bvh"
    write_keys_bvh(path, doll, keys, scale=100.0)
    _, _, positions = independent_fk(path.read_text())
    for f, key in enumerate(keys):
        assert np.abs(positions[f] / 100.0 - key_heads(doll, key)).max() <= 1e-4 * doll.size
    assert np.abs(positions[0] / 100.0 - key_heads(doll, keys[0])).max() <= 1e-9 * doll.size


def test_format_is_deterministic_and_portable(tmp_path, doll) -> None:
    keys = pose_keys(doll, "ZXY", seed=1)
    a, b = tmp_path / "a.bvh", tmp_path / "b.bvh"
    write_keys_bvh(a, doll, keys)
    write_keys_bvh(b, doll, KeyframeSet(keys))  # what `pose` holds
    data = a.read_bytes()
    assert data == b.read_bytes()
    assert b"\r" not in data and data.endswith(b"\n") and not data.endswith(b"\n\n")
    text = data.decode("ascii")
    lines = text.split("\n")
    assert lines[:4] == [
        "HIERARCHY",
        "ROOT hips",
        "{",
        "\tOFFSET 0.000000000 0.000000000 0.000000000",
    ]
    assert lines[4] == "\tCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation"
    assert text.count("CHANNELS 3 Zrotation Xrotation Yrotation") == len(doll.names) - 1
    leaves = [i for i in range(len(doll.names)) if i not in set(doll.parents)]
    assert text.count("End Site") == len(leaves)
    assert f"Frames: {len(keys)}\nFrame Time: 0.03333333333\n" in text
    numbers = re.findall(r"\S+", text.split("Frame Time:")[1])[1:]
    assert len(numbers) == len(keys) * (3 + 3 * len(doll.names))
    assert all(re.fullmatch(r"-?\d+\.\d+", n) and n != "-0.000000" for n in numbers)


@pytest.mark.parametrize(
    ("fps", "text"),
    [
        (30, "0.03333333333"),
        (120, "0.008333333333"),
        (24, "0.04166666667"),
        (25, "0.04"),
        (1, "1.0"),
    ],
)
def test_frame_time_has_ten_significant_digits(doll, fps, text) -> None:
    keys = pose_keys(doll, "ZXY", 0)[:1]
    assert f"Frame Time: {text}\n" in bvh_text(doll, keys, "ZXY", 1.0, 1.0 / fps)


def turning_keys(skel: Skeleton, axis: str, step: float, n: int) -> list[Keyframe]:
    """Every joint turning about one world axis by ``step`` degrees per key."""
    angles = np.arange(n) * step
    q = Rotation.from_euler(axis, angles[:, None], degrees=True).as_quat(scalar_first=True)
    local = np.repeat(q[:, None, :], len(skel.names), axis=1)
    return rigid_keys(skel, local, np.tile(skel.head0[0], (n, 1)))


@pytest.mark.parametrize(("axis", "slot"), [("Z", 0), ("X", 1), ("Y", 2)])
def test_angles_are_unwrapped_through_180_and_gimbal_lock(doll, axis, slot) -> None:
    """A steady 25°/key turn about one channel's axis reads back as 25·k in that channel,
    through ±180° and (for the middle X of ZXY) through the ±90° singularity."""
    keys = turning_keys(doll, axis, 25.0, 30)
    bvh = bvh_from_text(bvh_text(doll, keys, "ZXY", 1.0, 1 / 30))
    values = bvh.frames[:, 3:].reshape(len(keys), -1, 3)
    expected = np.zeros((len(keys), 3))
    expected[:, slot] = 25.0 * np.arange(len(keys))
    for joint in range(len(doll.names)):
        np.testing.assert_allclose(values[:, joint], expected, atol=1e-5)


def test_each_frame_takes_the_triple_nearest_the_previous_one(doll) -> None:
    """Brute force: of both Euler triples of each rotation and all their ±360° shifts, the
    written one is the nearest to the previous frame's (a random walk, also near lock)."""
    rng = np.random.default_rng(5)
    rotvec = np.cumsum(rng.normal(0.0, 0.15, (60, len(doll.names), 3)), axis=0)
    local = Rotation.from_rotvec(rotvec.reshape(-1, 3)).as_quat(scalar_first=True)
    keys = rigid_keys(doll, local.reshape(60, -1, 4), np.tile(doll.head0[0], (60, 1)))
    written = bvh_from_text(bvh_text(doll, keys, "ZXY", 1.0, 1 / 30)).frames[:, 3:]
    written = written.reshape(60, -1, 3)
    turns = np.array(np.meshgrid(*[np.arange(-3, 4)] * 3)).reshape(3, -1).T * 360.0
    for f in range(1, 60):
        for j, name in enumerate(_depth_first_names(doll)):
            q = keys[f].bones[name].local
            a = Rotation.from_quat(q, scalar_first=True).as_euler("ZXY", degrees=True)
            b = np.array([a[0] + 180.0, 180.0 - a[1], a[2] + 180.0])
            candidates = np.vstack((a + turns, b + turns))
            best = np.min(np.linalg.norm(candidates - written[f - 1, j], axis=1))
            mine = np.linalg.norm(written[f, j] - written[f - 1, j])
            assert mine <= best + 1e-5  # degrees; the file rounds to 1e-6


def _depth_first_names(skel: Skeleton) -> list[str]:
    return list(bvh_from_text(bvh_text(skel, [], "ZXY", 1.0, 1.0)).names)


def test_slerp_resampling_matches_scipy(tmp_path, doll) -> None:
    rng = np.random.default_rng(11)
    times = np.array([0.0, 0.4, 1.0])
    local = np.array([random_quats(len(doll.names), rng) for _ in times])
    root = rng.uniform(-1.0, 1.0, (3, 3))
    keys = rigid_keys(doll, local, root, times)
    path = tmp_path / "motion.bvh"
    write_keys_bvh(path, doll, keys, order="YZX", fps=10.0, interpolate="slerp")
    bvh = read_bvh(path)
    t = np.arange(11) / 10.0
    assert bvh.nframes == 11 and abs(bvh.frame_time - 0.1) < 1e-12
    trans, rot = bvh.poses()
    for axis in range(3):
        np.testing.assert_allclose(trans[:, 0, axis], np.interp(t, times, root[:, axis]), atol=1e-9)
    for b, name in enumerate(bvh.names):
        i = doll.names.index(name)
        want = Slerp(times, Rotation.from_quat(local[:, i], scalar_first=True))(t)
        got = Rotation.from_quat(rot[:, b], scalar_first=True)
        assert np.all((want.inv() * got).magnitude() < 1e-7)


def test_resample_covers_the_key_span() -> None:
    keys = [Keyframe(time=t, label="", bones={}) for t in (0.2, 0.5, 1.25)]
    frames = resample_keys(keys, 4.0)
    np.testing.assert_allclose([k.time for k in frames], 0.2 + np.arange(5) * 0.25)


def test_names_become_single_tokens() -> None:
    assert bvh_names(["a b", "a_b", "x{y}", "mixamorig:Hips", ""]) == (
        "a_b",
        "a_b_2",
        "x_y_",
        "mixamorig:Hips",
        "joint",
    )


def test_bad_arguments_raise(doll) -> None:
    keys = pose_keys(doll, "ZXY", 0)[:1]
    with pytest.raises(ValueError, match="order"):
        bvh_text(doll, keys, "XYX", 1.0, 0.1)
    with pytest.raises(ValueError, match="scale"):
        bvh_text(doll, keys, "ZXY", 0.0, 0.1)
    with pytest.raises(ValueError, match="interpolate"):
        write_keys_bvh(Path("unused.bvh"), doll, keys, interpolate="linear")
