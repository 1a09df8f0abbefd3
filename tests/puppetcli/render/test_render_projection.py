"""The golden pictures' joint dots against an independent projection (oracle: joint_marks).

Joint positions come from forward kinematics written in joint_marks (the rig as plain YAML,
scipy rotations), pixels from ``cv2.projectPoints`` with the frame's camera, the dots from
the picture's colours alone.  The mark finder itself is checked on dots drawn here by
exact area coverage, and the whole check is shown to reject the deliberate errors it is
for: a 1 % focal length, a half-pixel principal point, swapped image axes, a mirror.
"""

from __future__ import annotations

import math
from dataclasses import replace

import cv2
import numpy as np
import pytest
from joint_marks import (
    GOLDEN_ARM_DEG,
    JOINT_RED,
    WOOD_RED,
    check_joint_marks,
    find_marks,
    golden_pose,
)
from test_render_fixtures import doll, key
from test_render_golden import GOLDEN, VIEWS, framed, scene

from puppetcli.render.draw import LAYERS
from puppetcli.render.picture import poses_from_keys, render_pose
from puppetcli.render.scene import BONE_COLOR, JOINT_COLOR


def stored(view: str) -> np.ndarray:
    img = cv2.imread(str(GOLDEN / f"render_{view}.png"), cv2.IMREAD_COLOR)
    assert img is not None
    return img


def test_forward_kinematics_in_closed_form() -> None:
    """The raised arm swings rigidly about the shoulder; everything else stays at rest."""
    heads, tails = golden_pose()
    shoulder = np.array([0.18, 1.36, 0.0])  # rigs/doll.yaml: upper_arm_l's head
    a = math.radians(GOLDEN_ARM_DEG)
    arm = np.array([math.cos(a), math.sin(a), 0.0])
    assert np.allclose(tails["hand_l"], shoulder + (0.80 - 0.18) * arm, atol=1e-15)  # the tip
    assert np.allclose(heads["forearm_l"], shoulder + (0.46 - 0.18) * arm, atol=1e-15)
    assert np.allclose(heads["hand_r"], [-0.71, 1.36, 0.0], atol=1e-15)
    assert np.allclose(tails["foot_l"], [0.10, 0.045, 0.15], atol=1e-15)


def test_the_renderer_draws_the_independent_pose() -> None:
    """The pose the renderer takes from the golden key is the forward kinematics' pose."""
    _, skel = doll(props=True)
    (pose,) = poses_from_keys(skel, [key(skel, GOLDEN_ARM_DEG, 1.25, "golden")])
    heads, tails = golden_pose()
    assert np.abs(pose.head - [heads[n] for n in skel.names]).max() < 5e-16  # measured 1.1e-16
    assert np.abs(pose.tail - [tails[n] for n in skel.names]).max() < 5e-16  # measured 1.1e-16


def disc_picture(centres: np.ndarray, radius: float, size: int = 48) -> np.ndarray:
    """Dots of the joint colour on wood, each pixel blended by the disc's exact-ish area
    over it (16 × 16 samples per pixel): a drawing that shares nothing with the renderer."""
    sub = (np.arange(16) + 0.5) / 16 - 0.5
    v, u = np.indices((size, size), dtype=float)
    su = u[..., None, None] + sub[None, None, None, :]
    sv = v[..., None, None] + sub[None, None, :, None]
    cover = np.zeros((size, size))
    for cu, cv in centres:
        cover = np.maximum(cover, (((su - cu) ** 2 + (sv - cv) ** 2) < radius**2).mean(axis=(2, 3)))
    wood, joint = np.array(BONE_COLOR, float), np.array(JOINT_COLOR, float)
    return np.round(wood + cover[..., None] * (joint - wood)).astype(np.uint8)


def test_mark_finder_locates_dots_drawn_here() -> None:
    """Sub-pixel dots of the golden pictures' size (radius 0.6 … 1.2 px) are found at their
    centres: measured worst 0.076 px over 60 dots (the weights' wood threshold drops the
    thinnest edge pixels), a quarter of MARK_PX."""
    rng = np.random.default_rng(24)
    worst = 0.0
    for _ in range(20):
        centres = np.array([[12.0, 12.0], [36.0, 14.0], [20.0, 34.0]]) + rng.uniform(-3, 3, (3, 2))
        radius = rng.uniform(0.6, 1.2)
        marks = find_marks(disc_picture(centres, radius))
        assert len(marks) == 3
        for c in centres:
            worst = max(worst, float(np.linalg.norm(marks[:, :2] - c, axis=1).min()))
    assert worst < 0.15  # px, measured 0.076


def test_dots_and_wood_are_told_apart_by_colour() -> None:
    """The finder's thresholds sit between the wood and the dot in every drawn shade."""
    shades = [b for _, b in LAYERS] + [0.35]  # nested layers and the rim
    wood = (BONE_COLOR[2] - BONE_COLOR[1]) * max(shades)
    dot = (JOINT_COLOR[2] - JOINT_COLOR[1]) * min(shades)
    assert wood <= WOOD_RED < JOINT_RED < dot


@pytest.mark.parametrize("view", VIEWS)
def test_the_check_holds_at_every_sub_pixel_placement(view: str) -> None:
    """Pictures drawn through cameras zoomed ±3 % and moved ±0.5 px (each consistent with
    its camera) pass: the check's bounds are above its own spread (joint_marks)."""
    skel, pose, spec, framing = scene(view)
    rng = np.random.default_rng(5)
    for factor, shift in zip(
        rng.uniform(0.97, 1.03, 8), rng.uniform(-0.5, 0.5, (8, 2)), strict=True
    ):
        camera = zoomed(framing.camera, factor)
        camera = replace(camera, centre=camera.centre + shift)
        img = render_pose(skel, pose, spec, replace(framing, camera=camera))
        check_joint_marks(img, camera, view)


@pytest.mark.parametrize("which", ["rendered", "stored"])
@pytest.mark.parametrize("view", VIEWS)
def test_drawn_joints_lie_where_projected(view: str, which: str) -> None:
    """Measured (both pictures alike): farthest dot pixel 1.05–1.24 px from a joint, whole
    dots 0.02–0.18 px from theirs, fitted scale 1 + 8.5e-5 (front), 1 − 1.5e-4 (top)."""
    img, camera = framed(view)
    check_joint_marks(img if which == "rendered" else stored(view), camera, view)


def zoomed(camera, factor: float):
    """The camera with its focal length times ``factor``, zoomed about the picture's centre."""
    middle = 0.5 * (np.array(camera.size, float) - 1.0)
    centre = middle + factor * (camera.centre - middle)
    return replace(camera, focal=camera.focal * factor, centre=centre)


def rejects(img: np.ndarray, camera, view: str) -> bool:
    try:
        check_joint_marks(np.ascontiguousarray(img), camera, view)
    except AssertionError:
        return True
    return False


@pytest.mark.parametrize("factor", [1.01, 0.99])
@pytest.mark.parametrize("view", ["front", "top"])
def test_the_check_rejects_a_one_percent_focal_length(view: str, factor: float) -> None:
    """A golden drawn with a focal length 1 % off, or checked with one, fails: the whole
    dots' fitted scale is 0.95–1.05 % off (measured), the outer dots 0.33–0.55 px."""
    _, camera = framed(view)
    assert rejects(stored(view), zoomed(camera, factor), view)


@pytest.mark.parametrize("view", VIEWS)
def test_the_check_rejects_a_half_pixel_principal_point(view: str) -> None:
    """Measured: the worst whole dot 0.48–0.68 px from its joint."""
    _, camera = framed(view)
    for shift in ([0.5, 0.0], [0.0, 0.5], [-0.5, 0.0], [0.0, -0.5]):
        assert rejects(stored(view), replace(camera, centre=camera.centre + shift), view)


@pytest.mark.parametrize("view", VIEWS)
def test_the_check_rejects_swapped_axes_and_mirrors(view: str) -> None:
    """Swapped image axes fail in every view; a mirror fails wherever the joints are not
    symmetric about the mirror's axis (the doll is flat in z = 0 but for its feet, so the
    side view puts every joint on the middle column and the top view on the middle row)."""
    img, camera = framed(view)
    assert rejects(img.transpose(1, 0, 2), camera, view)
    if view != "top":
        assert rejects(img[::-1], camera, view)
    if view != "side":
        assert rejects(img[:, ::-1], camera, view)
    mirrored = replace(camera, axes=camera.axes * [[-1.0], [1.0], [1.0]])
    with pytest.raises(AssertionError, match="mirrored"):
        check_joint_marks(img, mirrored, view)
