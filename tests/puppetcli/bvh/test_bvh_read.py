"""BVH reader: agreement with the third-party ``bvh`` package and an independent FK,
tolerated variations, and one ``<file>:<line>: expected …, got …`` line per problem."""

from __future__ import annotations

import bvh as bvh_package
import numpy as np
import pytest
from test_bvh_fixtures import independent_fk, make_bvh

from puppetcli.bvh.model import BvhError
from puppetcli.bvh.read import bvh_from_text, read_bvh

CASES = [("simple19", "XYZ"), ("cmu31", "ZYX"), ("cmu31", "mixed"), ("mixamo65", "ZYX")]

SMALL = """\
HIERARCHY
ROOT Hips
{
\tOFFSET 0 90 0
\tCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
\tJOINT Chest
\t{
\t\tOFFSET 0 10 0
\t\tCHANNELS 3 Zrotation Xrotation Yrotation
\t\tEnd Site
\t\t{
\t\t\tOFFSET 0 5 0
\t\t}
\t}
}
MOTION
Frames: 2
Frame Time: 0.0333333333
0 0 0 90 90 0 0 0 0
1 2 3 0 0 0 0 0 0
"""


@pytest.mark.parametrize(("kind", "order"), CASES)
def test_structure_and_values_match_the_bvh_package(kind, order) -> None:
    text = make_bvh(kind, order, frames=4)
    ours = bvh_from_text(text)
    theirs = bvh_package.Bvh(text)
    assert list(ours.names) == theirs.get_joints_names()
    for i, joint in enumerate(ours.joints):
        assert joint.parent == theirs.joint_parent_index(joint.name)
        assert list(joint.channels) == theirs.joint_channels(joint.name)
        np.testing.assert_array_equal(joint.offset, theirs.joint_offset(joint.name))
        assert ours.channel_starts()[i] == theirs.get_joint_channels_index(joint.name)
    np.testing.assert_array_equal(ours.frames, np.array(theirs.frames, dtype=float))
    assert ours.frame_time == theirs.frame_time and ours.nframes == theirs.nframes == 4


@pytest.mark.parametrize(("kind", "order"), CASES)
def test_forward_kinematics_matches_scipy_matrices(kind, order) -> None:
    text = make_bvh(kind, order, frames=4)
    bvh = bvh_from_text(text)
    _, _, positions = independent_fk(text)
    size = np.ptp(positions[0], axis=0).max()
    for f in range(4):
        heads, _ = bvh.forward_kinematics(f)
        assert np.abs(heads - positions[f]).max() <= 1e-12 * size


def test_worked_example_and_end_sites() -> None:
    """formats.md §1.3: ZXY with Z = X = 90° sends a child at OFFSET (0, 10, 0) to (0, 0, 10)."""
    bvh = bvh_from_text(SMALL)
    heads, world = bvh.forward_kinematics(0)
    np.testing.assert_allclose(heads, [[0, 0, 0], [0, 0, 10]], atol=1e-12)
    np.testing.assert_allclose(bvh.end_sites(heads, world)[1], [[0, 0, 15]], atol=1e-12)
    rest, _ = bvh.forward_kinematics(None)  # the rest pose: root at its (non-zero) OFFSET
    np.testing.assert_allclose(rest, [[0, 90, 0], [0, 100, 0]])
    heads, _ = bvh.forward_kinematics(1)  # position channels replace the root OFFSET
    np.testing.assert_allclose(heads, [[1, 2, 3], [1, 12, 3]])


def test_crlf_tabs_spaces_and_case_are_tolerated() -> None:
    want = bvh_from_text(make_bvh("cmu31", "mixed"))
    variant = make_bvh("cmu31", "mixed", newline="\r\n", indent="  ")
    variant = variant.replace("JOINT", "joint").replace("OFFSET", "Offset").replace(" ", "\t ")
    got = bvh_from_text(variant)
    assert got.names == want.names
    np.testing.assert_array_equal(got.frames, want.frames)
    assert [j.channels for j in got.joints] == [j.channels for j in want.joints]


def test_six_channel_joints_braces_on_header_lines_and_odd_names() -> None:
    text = """HIERARCHY
ROOT Body Root {
OFFSET 1 2 3
CHANNELS 3 Yrotation Xrotation Zrotation
JOINT mixamorig:Arm {
OFFSET 10 0 0
CHANNELS 6 Zrotation Xposition Yposition Zposition Xrotation Yrotation
End Site {
OFFSET 0 0 0
}
}
}
MOTION
Frames: 1
Frame Time: 0.1
90 0 0 0 5 6 7 0 0
"""
    bvh = bvh_from_text(text)
    assert bvh.names == ("Body Root", "mixamorig:Arm")
    assert bvh.joints[1].rotation_order == "ZXY"
    heads, _ = bvh.forward_kinematics(0)
    # The root turns 90° about Y: the child's position channels (5, 6, 7) replace its
    # OFFSET, in the root's frame → (1, 2, 3) + Ry(90°)·(5, 6, 7) = (1 + 7, 2 + 6, 3 − 5).
    np.testing.assert_allclose(heads[1], [8, 8, -2], atol=1e-12)


def test_zero_length_bones_are_read() -> None:
    bvh = bvh_from_text(make_bvh("cmu31", "ZYX"))
    heads, _ = bvh.forward_kinematics(None)
    i = bvh.names.index("LHipJoint")
    np.testing.assert_array_equal(heads[i], heads[0])


def test_read_bvh_names_the_file(tmp_path) -> None:
    path = tmp_path / "bad.bvh"
    path.write_bytes(b"HIERARCHY\nROOT a\n{\n\xff\n")
    with pytest.raises(BvhError, match=r"bad\.bvh:4: expected UTF-8 text"):
        read_bvh(path)
    with pytest.raises(BvhError, match="cannot read"):
        read_bvh(tmp_path / "missing.bvh")


def _line_of(text: str, needle: str) -> int:
    return text[: text.index(needle)].count("\n") + 1


# (name, edit of SMALL, line of the error, expected message after "<file>:<line>: ")
BAD = [
    ("missing {", lambda t: t.replace("ROOT Hips\n{\n", "ROOT Hips\n"), 3,
     "expected '{' opening ROOT 'Hips', got 'OFFSET 0 90 0'"),
    ("missing }", lambda t: t.replace("\t}\n}\nMOTION", "\t}\nMOTION"), 15,
     "expected 'JOINT', 'End Site' or '}' closing ROOT 'Hips' (line 2), got 'MOTION'"),
    ("channel count", lambda t: t.replace("CHANNELS 3 Zrotation Xrotation Yrotation",
     "CHANNELS 3 Zrotation Xrotation"), 9, "expected 3 channel names after 'CHANNELS 3', got 2"),
    ("unknown channel", lambda t: t.replace("3 Zrotation Xrotation Yrotation",
     "3 Zrotation Xrot Yrotation"), 9,
     "expected a channel name (Xposition … Zrotation) (did you mean 'Xrotation'?), got 'Xrot'"),
    ("fewer frames", lambda t: t.replace("Frames: 2", "Frames: 3"), 17,
     "expected 3 frame lines after 'Frame Time:' (Frames: 3), got 2"),
    ("non-numeric", lambda t: t.replace("1 2 3 0", "1 2 x3 0"), 20, "expected a number, got 'x3'"),
    ("nan", lambda t: t.replace("1 2 3 0", "1 2 nan 0"), 20, "expected a finite number, got 'nan'"),
    ("short frame line", lambda t: t.replace("1 2 3 0 0 0 0 0 0", "1 2 3 0 0 0 0 0"), 20,
     "expected 9 values in frame 1 (one per channel), got 8"),
    ("offset", lambda t: t.replace("OFFSET 0 10 0", "OFFSET 0 10"), 8,
     "expected 3 numbers after OFFSET of JOINT 'Chest', got 2"),
    ("more frames", lambda t: t + "1 2 3 0 0 0 0 0 0\n", 21,
     "expected the end of the file after 2 frames (Frames: 2), got more lines"),
    ("second root", lambda t: t.replace("MOTION", "ROOT Other\n{\n}\nMOTION"), 16,
     "expected 'MOTION' (one ROOT per file), got a second 'ROOT'"),
    ("no hierarchy", lambda t: t.replace("HIERARCHY\n", "\n"), 2,
     "expected 'HIERARCHY' as the first word of the file, got 'ROOT'"),
    ("frame time", lambda t: t.replace("Frame Time: 0.0333333333", "Frame Time: 0"), 18,
     "expected a positive frame time (seconds per frame), got '0'"),
    ("truncated", lambda t: t[: t.index("\tJOINT")], 6,
     "expected 'JOINT', 'End Site' or '}' closing ROOT 'Hips' (line 2), got end of file"),
]  # fmt: skip


@pytest.mark.parametrize(("name", "edit", "line", "message"), BAD, ids=[b[0] for b in BAD])
def test_bad_input_is_one_clear_line(name, edit, line, message) -> None:
    with pytest.raises(BvhError) as info:
        bvh_from_text(edit(SMALL), "walk.bvh")
    assert str(info.value) == f"walk.bvh:{line}: {message}"
    assert "\n" not in str(info.value)


def test_euler_angles_agree_with_scipy():
    """bvh's own quaternion ↔ intrinsic Euler conversions against scipy's Rotation (an
    independent implementation), on random rotations and at gimbal lock."""
    from scipy.spatial.transform import Rotation

    from puppetcli.bvh.model import ORDERS, euler_from_quat, quat_from_euler

    q = Rotation.random(5000, random_state=np.random.default_rng(7)).as_quat(scalar_first=True)
    for order in ORDERS:
        angles = euler_from_quat(q, order)
        want = Rotation.from_quat(q, scalar_first=True).as_euler(order, degrees=True)
        assert np.abs(angles - want).max() < 1e-11  # degrees; measured 1.1e-12
        again = Rotation.from_euler(order, angles, degrees=True).as_quat(scalar_first=True)
        assert np.abs(quat_from_euler(angles, order) - again).max() < 1e-15  # measured 0
        locked = Rotation.from_euler(order, [[30.0, 90.0, 0.0], [-50.0, -90.0, 0.0]], degrees=True)
        assert np.allclose(euler_from_quat(locked.as_quat(scalar_first=True), order),
                           [[30.0, 90.0, 0.0], [-50.0, -90.0, 0.0]], atol=1e-9)  # fmt: skip
