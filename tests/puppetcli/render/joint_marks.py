"""Where the golden pictures' joint dots must be, computed without puppetcli.render.

The oracle for test_render_golden.py and test_render_projection.py:

- joint positions: forward kinematics written here, from rigs/doll.yaml read as plain YAML
  and the golden key's meaning (the T-pose with the left upper arm turned
  ``GOLDEN_ARM_DEG`` about world +z at the shoulder; every other joint at rest), with
  scipy rotations; a bone's head is its parent's head plus the parent's rotation of the
  rest offset between them, its tail its head plus its own rotation of its rest vector;
- pixels: ``cv2.projectPoints`` with the extrinsics and intrinsics read off the frame's
  ``Camera`` (rows of ``axes`` = OpenCV's camera x, y, z in the world; ``eye``; ``focal``;
  ``centre``), converted here to rvec, tvec and K;
- marks: the joint dots found in a picture by their colour alone.  The dots are a strong
  red (BGR 51, 64, 191: red − green = 127 at full shade, 44 at the darkest rim shade
  0.35); the wood of the bones has red − green at most 26 × 1.12 = 29.1, the background,
  ground, grid, shadows, props and text at most 0.  So a pixel with red − green above
  ``JOINT_RED`` shows (part of) a dot.  Such pixels, grown by one pixel, are grouped in
  8-connected marks, a group split between the joints nearest its pixels where two dots
  touch (neck and head seen from the front, 3.9 px apart); joints nearer each other than
  ``MERGE_PX`` count as one (one dot hides the other).  A mark's position is its centroid
  weighted by red − green above ``WOOD_RED`` (wood weighs nothing).  A whole dot at 96 ×
  96 px covers 2 × 2 to 3 × 3 pixels; a mark lighter than ``WHOLE`` × the heaviest is a
  dot partly hidden (by the table, a nearer limb): it gives no centre, but like every dot
  pixel it must lie near a joint.

``joint_mark_report`` measures a picture against a camera; ``check_joint_marks`` asserts
the measured bounds below for one of the golden views.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import yaml
from scipy.spatial.transform import Rotation

DOLL = Path(__file__).resolve().parents[3] / "rigs" / "doll.yaml"
GOLDEN_ARM_DEG = 40.0  # the golden key: left arm raised this much about +z at the shoulder
JOINT_RED = 40  # red − green (grey levels) above which a pixel shows a joint dot
WOOD_RED = 30  # red − green above the brightest wood (29): weights are counted above it
WHOLE = 0.6  # least weight of a whole dot, relative to the heaviest mark
MERGE_PX = 2.5  # joints nearer than this (px) in the picture: their dots overlap
# Bounds, measured on the golden scene at 96 × 96, rendered now and stored (identical), and
# (in brackets) the worst over 160 renders of it through cameras zoomed ±3 % and moved
# ±0.5 px, which put the dots at other sub-pixel phases (test_render_projection draws 32):
STRAY_PX = 2.0  # every dot pixel this near a projected joint; measured 1.24 (1.35)
MARK_PX = 0.35  # each whole mark this near its joint; measured 0.181 (0.231)
SCALE = 0.004  # |fitted scale − 1| with ≥ FIT_MARKS whole marks; measured 1.5e-4 (2.5e-3)
FIT_MARKS = 4
# Whole marks each view must show, joints in plain sight there: front, both arms (6), neck,
# head, chest and both knees; top, both hands, the right elbow and shoulder, the head;
# side, the near knee and ankle; iso, the head and the chest (measured: 11, 5, 2, 2).
MIN_MARKS = {"front": 10, "top": 4, "side": 2, "iso": 2}


def forward_kinematics(local: dict[str, Rotation]) -> tuple[dict, dict]:
    """(heads, tails) by bone name, world frame (m), of the doll with joint rotations
    ``local`` (rotation of each bone relative to its parent, from rest; absent = rest)."""
    bones = yaml.safe_load(DOLL.read_text())["bones"]
    rest = {b["name"]: b for b in bones}
    world, heads, tails = {}, {}, {}
    for b in bones:  # parents come first in the rig
        name, parent = b["name"], b.get("parent")
        turn = local.get(name, Rotation.identity())
        if parent is None:
            world[name], heads[name] = turn, np.array(b["head"], float)
        else:
            world[name] = world[parent] * turn
            offset = np.subtract(b["head"], rest[parent]["head"], dtype=float)
            heads[name] = heads[parent] + world[parent].apply(offset)
        tails[name] = heads[name] + world[name].apply(np.subtract(b["tail"], b["head"]))
    return heads, tails


def golden_pose() -> tuple[dict, dict]:
    """(heads, tails) of the golden key."""
    raised = Rotation.from_rotvec([0.0, 0.0, math.radians(GOLDEN_ARM_DEG)])
    return forward_kinematics({"upper_arm_l": raised})


def golden_joints() -> tuple[list[str], np.ndarray]:
    """(names, world positions (n, 3)) of the drawn joints: every non-root bone's head."""
    bones = yaml.safe_load(DOLL.read_text())["bones"]
    heads, _ = golden_pose()
    names = [b["name"] for b in bones if b.get("parent")]
    return names, np.array([heads[n] for n in names])


def opencv_camera(camera) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(rvec, tvec, K) of a renderer ``Camera``: x_cam = R (p − eye), R's rows = ``axes``."""
    axes = np.asarray(camera.axes, float)
    assert np.abs(axes @ axes.T - np.eye(3)).max() < 1e-12, "camera axes not orthonormal"
    assert np.linalg.det(axes) > 0, "camera axes mirrored (a left-handed frame)"
    rvec, _ = cv2.Rodrigues(axes)
    tvec = -axes @ np.asarray(camera.eye, float)
    cx, cy = camera.centre
    k = np.array([[camera.focal, 0.0, cx], [0.0, camera.focal, cy], [0.0, 0.0, 1.0]])
    return rvec, tvec, k


def project(points: np.ndarray, camera) -> np.ndarray:
    """Pixels (n, 2) of world points with ``cv2.projectPoints``."""
    rvec, tvec, k = opencv_camera(camera)
    pixels, _ = cv2.projectPoints(np.asarray(points, float).reshape(-1, 3), rvec, tvec, k, None)
    return pixels.reshape(-1, 2)


def dot_pixels(img: np.ndarray) -> np.ndarray:
    """Boolean (H, W): pixels that show part of a joint dot (BGR picture)."""
    bgr = img.astype(int)
    return (bgr[..., 2] - bgr[..., 1]) > JOINT_RED


def clusters(pixels: np.ndarray) -> np.ndarray:
    """(n,) a label per projected joint: joints nearer than ``MERGE_PX`` to each other,
    directly or through others, share one (their dots overlap: one hides the other)."""
    label = np.arange(len(pixels))
    near = np.linalg.norm(pixels[:, None] - pixels[None], axis=2) < MERGE_PX
    for _ in range(len(pixels)):
        label = np.array([label[near[i]].min() for i in range(len(pixels))])
    return label


def find_marks(img: np.ndarray, pixels: np.ndarray | None = None) -> np.ndarray:
    """(n, 3): u, v (px, pixel centres at integers) and weight of every mark.  With the
    projected joints ``pixels``, a group of dot pixels is split between the clusters of
    joints nearest to its pixels (dots of joints a few pixels apart can touch)."""
    bgr = img.astype(int)
    weight = np.clip(bgr[..., 2] - bgr[..., 1] - WOOD_RED, 0, None).astype(float)
    grown = cv2.dilate(dot_pixels(img).astype(np.uint8), np.ones((3, 3), np.uint8))
    _, labels = cv2.connectedComponents(grown, connectivity=8)
    v, u = np.indices(labels.shape)
    if pixels is not None:
        grid = np.stack((u, v), axis=-1).astype(float)
        nearest = np.argmin(np.linalg.norm(grid[:, :, None] - pixels, axis=3), axis=2)
        labels = labels * len(pixels) + clusters(pixels)[nearest]
        labels[grown == 0] = 0
    marks = []
    for k in np.unique(labels[labels > 0]):
        w = weight * (labels == k)
        if w.sum() > 0:
            marks.append(((w * u).sum() / w.sum(), (w * v).sum() / w.sum(), w.sum()))
    return np.array(marks).reshape(-1, 3)


@dataclass(frozen=True)
class MarkReport:
    """A picture against a camera: the farthest dot pixel from any projected joint (px);
    each whole mark's joint and its distance from that joint's projection (px); the
    fitted scale of the whole marks about the picture's centre (None: too few marks)."""

    stray: float
    joints: list[str]
    errors: np.ndarray
    scale: float | None


def joint_mark_report(img: np.ndarray, camera) -> MarkReport:
    names, points = golden_joints()
    pixels = project(points, camera)
    v, u = np.nonzero(dot_pixels(img))
    found = np.stack((u, v), axis=1)
    stray = max((float(np.linalg.norm(pixels - p, axis=1).min()) for p in found), default=0.0)
    marks = find_marks(img, pixels)
    whole = marks[marks[:, 2] >= WHOLE * marks[:, 2].max()] if len(marks) else marks
    nearest = [int(np.argmin(np.linalg.norm(pixels - m[:2], axis=1))) for m in whole]
    errors = np.array(
        [np.linalg.norm(pixels[j] - m[:2]) for j, m in zip(nearest, whole, strict=True)]
    )
    scale = None
    if len(whole) >= FIT_MARKS:
        # whole − c = s (projected − c) + t, least squares: s, tx, ty.
        centre = 0.5 * (np.array(img.shape[1::-1], float) - 1.0)
        p, d = pixels[nearest] - centre, whole[:, :2] - centre
        a = np.zeros((2 * len(p), 3))
        a[0::2, 0], a[1::2, 0], a[0::2, 1], a[1::2, 2] = p[:, 0], p[:, 1], 1.0, 1.0
        scale = float(np.linalg.lstsq(a, d.reshape(-1), rcond=None)[0][0])
    return MarkReport(stray, [names[j] for j in nearest], errors, scale)


def check_joint_marks(img: np.ndarray, camera, view: str) -> MarkReport:
    """Assert that the picture's joint dots lie where the camera projects the joints."""
    report = joint_mark_report(img, camera)
    assert report.stray < STRAY_PX, (view, "a dot away from every joint", report)
    assert len(report.errors) >= MIN_MARKS[view], (view, "too few whole dots", report)
    assert report.errors.max() < MARK_PX, (view, "a dot off its joint", report)
    if report.scale is not None:
        assert abs(report.scale - 1.0) < SCALE, (view, "dots scaled about the centre", report)
    return report
