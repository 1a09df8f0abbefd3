"""BVH files render as they are: posed correctly on any rig made from them, on the ground.

Independent values: joint positions from ``independent_fk`` (the third-party ``bvh``
package + scipy matrices); the rig's own rest picture (a pose that needs no BVH at all);
the rig's ground height and bone radii from its YAML.
"""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np
import pytest
from click.testing import CliRunner
from test_bvh_fixtures import SKELETONS, bvh_text, channel_lists, independent_fk, random_frames

from puppetcli.bvh.model import ORDERS
from puppetcli.bvh.read import bvh_from_text
from puppetcli.bvh.rig import rig_text_from_bvh
from puppetcli.bvh.units import infer_unit
from puppetcli.cli import cli
from puppetcli.render.inputs import key_poses
from puppetcli.render.picture import frame_poses, render_pose
from puppetcli.render.scene import Pose
from puppetcli.rig.load import rig_from_text
from puppetcli.rig.skeleton import Skeleton
from solver import quat

FRAMES = 4


def _file(kind: str, order: str, factor: float = 1.0, newline: str = "\n", seed: int = 3) -> str:
    """A ``kind`` skeleton, OFFSETs × ``factor``, random frames (non-zero rotations in every
    frame, root positions near its OFFSET), ``order`` per joint or ``mixed``."""
    joints = [
        replace(j, offset=tuple(factor * v for v in j.offset),
                end=None if j.end is None else tuple(factor * v for v in j.end))
        for j in SKELETONS[kind]()
    ]  # fmt: skip
    rng = np.random.default_rng(seed)
    orders = [ORDERS[k] for k in rng.integers(0, 6, len(joints))] if order == "mixed" else None
    channels = channel_lists(joints, orders or [order] * len(joints))
    frames = random_frames(joints, channels, FRAMES, seed)
    return bvh_text(joints, channels, frames, newline=newline)


FILES = {
    "metres, root OFFSET": lambda: _file("simple19", "XYZ"),
    "centimetres, mixed orders": lambda: _file("mixamo65", "mixed"),
    "CMU units, CRLF": lambda: _file("cmu31", "ZYX", newline="\r\n"),
    "inches, mixed orders": lambda: _file("simple19", "mixed", factor=1 / 0.0254),
}


def _rig(tmp_path, text: str, frame: int | None):
    path = tmp_path / "motion.bvh"
    path.write_bytes(text.encode())
    bvh = bvh_from_text(text, str(path))
    spec = rig_from_text(rig_text_from_bvh(bvh, "m", infer_unit(bvh).scale, frame), "rig")
    return path, spec, Skeleton.from_spec(spec)


@pytest.mark.parametrize("name", FILES)
@pytest.mark.parametrize("frame", [0, 2])
def test_frame_n_is_the_rest_picture_of_a_rig_made_from_frame_n(tmp_path, name, frame) -> None:
    """Rendered frame N of a rig made with ``--frame N`` equals the rig's own rest picture,
    pixel for pixel (bones once rotated, standing on their joints)."""
    path, spec, skel = _rig(tmp_path, FILES[name](), frame)
    (pose,) = key_poses(path, "bvh", skel, spec, [frame])
    rest = Pose(skel.head0, skel.tail0, np.tile(quat.IDENTITY, (len(skel.names), 1)))
    framing = frame_poses(skel, [rest], spec, "iso", (160, 160))
    drawn = render_pose(skel, pose, spec, framing, caption=False)
    expected = render_pose(skel, rest, spec, framing, caption=False)
    assert np.array_equal(drawn, expected)
    # The rig file rounds to 10 decimals (5e-11 m): measured 3.3e-11 × size.
    assert np.abs(pose.head - skel.head0).max() < 1e-10 * skel.size


@pytest.mark.parametrize("name", FILES)
@pytest.mark.parametrize("rig_frame", [None, 1])
def test_bones_reach_their_childrens_joints_in_every_frame(tmp_path, name, rig_frame) -> None:
    """In every frame, on a rig made from the OFFSETs or from frame 1: heads are the file's
    joints (scaled, one vertical shift for the whole motion) and a one-child bone's tail,
    drawn from its rotation, is its child's joint."""
    text = FILES[name]()
    path, spec, skel = _rig(tmp_path, text, rig_frame)
    poses = key_poses(path, "bvh", skel, spec, list(range(FRAMES)))
    names, parents, joints = independent_fk(text)
    assert names == list(skel.names)
    scale = infer_unit(bvh_from_text(text, "x")).scale
    shift = poses[0].head[0] - scale * joints[0, 0]
    assert np.abs(shift[[0, 2]]).max() < 1e-10 * skel.size  # vertical only (rig rounding)
    only_child = {p: c for c, p in enumerate(parents) if p >= 0 and list(parents).count(p) == 1}
    worst = 0.0
    for f, pose in enumerate(poses):
        worst = max(worst, np.abs(pose.head - (scale * joints[f] + shift)).max())
        for b, c in only_child.items():
            worst = max(worst, np.abs(pose.tail[b] - (scale * joints[f, c] + shift)).max())
    # Measured 1.2e-10 × size: the rig file's 10 decimals (4e-16 on rigs from the OFFSETs).
    assert worst < 5e-10 * skel.size


@pytest.mark.parametrize("name", FILES)
def test_a_motion_stands_on_the_ground(tmp_path, name) -> None:
    """A rig made from the OFFSETs has its ground under the rest pose; the motion is moved
    vertically, once, by s (the drawn heads less the file's joints from an independent FK):
    either s = 0 and the motion was already within 5 % of the figure's size of the ground,
    or |s| is more than that and the lowest point over all frames now touches it."""
    text = FILES[name]()
    path, spec, skel = _rig(tmp_path, text, None)
    poses = key_poses(path, "bvh", skel, spec, list(range(FRAMES)))
    _, _, joints = independent_fk(text)
    scale = infer_unit(bvh_from_text(text, "x")).scale
    shift = np.array([p.head - scale * joints[f] for f, p in enumerate(poses)])
    assert np.abs(shift - shift[0, 0]).max() < 1e-9 * skel.size  # one shift for all
    assert np.abs(shift[0, 0, [0, 2]]).max() < 1e-12 * skel.size  # vertical only
    low = []
    for pose in poses:
        for i, kind in enumerate(skel.shape):
            ends = (pose.head[i, 1], pose.tail[i, 1])
            y = min(ends) if kind == "capsule" else 0.5 * sum(ends)
            low.append(y - skel.radius[i])
    gap, moved = min(low) - spec.ground.height, float(shift[0, 0, 1])
    slack = 0.05 * skel.size
    if abs(moved) < 1e-9 * skel.size:  # not moved: the two FKs' rounding, 1e-12 m
        assert abs(gap) <= slack
    else:
        assert abs(moved) > slack and gap == pytest.approx(0.0, abs=1e-12)


def test_a_capture_with_its_hips_up_is_set_down(tmp_path) -> None:
    """CMU-style: ROOT OFFSET 0 and the root channels 17 units up: the default rig's
    rest pose hangs below the origin, the motion is lowered onto its ground (and says so)."""
    joints = SKELETONS["cmu31"]()
    channels = channel_lists(joints, ["ZYX"] * len(joints))
    frames = random_frames(joints, channels, FRAMES, 0, spread=10.0)
    frames[:, 1] += 17.0  # Yposition of the root
    path = tmp_path / "capture.bvh"
    path.write_text(bvh_text(joints, channels, frames))
    result = CliRunner().invoke(cli, ["render", str(path), "-o", str(tmp_path / "s.png")])
    assert result.exit_code == 0, result.output
    assert "assuming CMU units" in result.stderr
    assert "motion lowered 0.9" in result.stderr  # 17 units × 0.0564 m less the legs' reach
    assert cv2.imread(str(tmp_path / "s.png")).shape == (480, 4 * 480, 3)


def test_render_a_bvh_without_a_rig_and_pick_frames(tmp_path) -> None:
    path = tmp_path / "walk.bvh"
    path.write_text(_file("mixamo65", "ZYX"))
    out = tmp_path / "s.png"
    result = CliRunner().invoke(
        cli, ["render", str(path), "-o", str(out), "--frame", "1", "--frame", "3", "--size",
              "64x48"],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    assert "assuming centimetres" in result.stderr
    assert cv2.imread(str(out)).shape == (48, 2 * 64, 3)
    bad = CliRunner().invoke(cli, ["render", str(path), "-o", str(out), "--force", "--frame", "4"])
    assert bad.exit_code == 1
    assert bad.stderr.strip().splitlines()[-1] == (
        f"error: {path}: --frame: expected a frame from 0 to 3, got 4"
    )
