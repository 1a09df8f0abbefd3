"""What a picture of a pose contains, in world terms: bone shapes, joints, props, pointer, ground.

A bone is drawn as its rig shape: a capsule from head to tail, a sphere at the
midpoint, or a box centred at the midpoint whose local y runs head → tail
(orientation = key rotation ⊗ rest shape frame).  Joints (every non-root bone's
head) are dots.  Static props are boxes and spheres at their rig pose.  The
ground (when the rig has one) is a grid of ``GRID_STEP`` squares covering the
fitted scene, with each bone's contact shadow: the bone projected straight down,
darker the nearer it is to the ground (linear fade to nothing at
``SHADOW_FADE`` m), capsules split in pieces so that a leaning limb darkens
towards the end that touches.  Joint dots, grid, shadow fade and the ground's
margin are sized for a figure of ``REFERENCE_SIZE``; a smaller figure (a doll
of 30 cm) gets them scaled down with it (``figure_factor``).

Occlusion is the painter's algorithm (``puppetcli.render.order``): every
drawable (a capsule, a sphere, one face of a box, a joint dot) gets the depth
of its centre and they are drawn far to near, refined by a plane test for flat
faces.  Interpenetrating or long crossing capsules can still be drawn in the
wrong order; for a doll's limbs this is rarely visible.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, replace

import cv2
import numpy as np

from puppetcli.render import draw as draw
from puppetcli.render.camera import NEAR, Camera
from puppetcli.render.order import Item, paint_order
from puppetcli.rig.skeleton import Skeleton
from solver import quat
from solver.massprops import shape_frame
from solver.spec import RigSpec

__all__ = [
    "Pose", "draw_ground", "draw_items", "figure_factor", "grid_step", "pose_extent", "prop_extent",
]  # fmt: skip

# Sizes for a figure of REFERENCE_SIZE m (the rest pose's bounding-box diagonal) or more; a
# smaller figure gets them scaled by its size / REFERENCE_SIZE (the grid step by a power of 10).
REFERENCE_SIZE = 2.0  # m
GRID_STEP = 0.25  # m between ground grid lines (× 10 while a side would have more lines)
MAX_GRID_LINES = 60
GRID_MARGIN = 0.3  # m of ground shown around the scene
SHADOW_FADE = 1.0  # m above the ground where a shadow fades out
SHADOW_DARK = 0.6  # darkening of the ground under a bone touching it
SHADOW_PIECES = 4  # pieces per capsule shadow
JOINT_RADIUS = 0.012  # m, joint dots
BONE_COLOR = (140, 191, 217)  # BGR, as the trace's bone colour
JOINT_COLOR = (51, 64, 191)
PROP_COLOR = (190, 165, 140)
POINTER_COLOR = (51, 77, 255)
COUPLING_COLOR = (26, 204, 255)
GROUND_COLOR = (214, 220, 218)
GRID_COLOR = (178, 186, 184)
_BOX_FACES = ((0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3))
_GROUND_CIRCLE = np.insert(draw.CIRCLE, 1, 0.0, axis=1)  # unit circle in the x-z plane
_SIGNS = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], float)


@dataclass(frozen=True)
class Pose:
    """One picture's content: bone head, tail (nb,3) m and rotation (nb,4) (w,x,y,z) in the
    skeleton's order; label; time (s); optional pointer centre (3,) m with its radius (m) and,
    in grip mode, the grip point (3,) m it is coupled to."""

    head: np.ndarray
    tail: np.ndarray
    rot: np.ndarray
    label: str = ""
    time: float = 0.0
    pointer: np.ndarray | None = None
    grip: np.ndarray | None = None
    pointer_radius: float = 0.02


def figure_factor(skel: Skeleton) -> float:
    """How much smaller than ``REFERENCE_SIZE`` the figure is, in (0, 1]: joint dots, the
    ground's margin, grid and shadow fade are scaled by it."""
    return float(np.clip(skel.size / REFERENCE_SIZE, 1e-6, 1.0))


def grid_step(skel: Skeleton) -> float:
    """``GRID_STEP`` × the power of ten at or below the figure factor."""
    return GRID_STEP * 10.0 ** math.floor(math.log10(figure_factor(skel)) + 1e-9)


def box_corners(centre: np.ndarray, q: np.ndarray, half: np.ndarray) -> np.ndarray:
    """The 8 corners (8, 3) of a box; index bits (x, y, z) = (4, 2, 1) pick the + sides."""
    return centre + quat.rotate(np.broadcast_to(q, (8, 4)), _SIGNS * half)


def bone_box(skel: Skeleton, pose: Pose, i: int) -> np.ndarray:
    """Corners (8, 3) of bone ``i``'s box in ``pose``."""
    q = quat.mul(pose.rot[i], shape_frame(skel.head0[i], skel.tail0[i]))
    return box_corners(0.5 * (pose.head[i] + pose.tail[i]), q, skel.half[i])


def prop_corners(prop) -> np.ndarray:
    """Corners (8, 3) of a box prop."""
    q = quat.normalize(np.asarray(prop.rotation, dtype=float))
    return box_corners(np.asarray(prop.position, float), q, np.asarray(prop.shape.half_extents))


def pose_extent(skel: Skeleton, pose: Pose) -> tuple[np.ndarray, np.ndarray]:
    """(points (n,3), radii (n,)) that a framing must hold to show ``pose`` whole."""
    pts, radii = [], []
    for i, kind in enumerate(skel.shape):
        if kind == "box":
            pts.append(bone_box(skel, pose, i))
            radii.append(np.zeros(8))
        else:
            ends = (pose.head[i], pose.tail[i])
            pts.append(np.array(ends if kind == "capsule" else [0.5 * (ends[0] + ends[1])]))
            radii.append(np.full(len(pts[-1]), skel.radius[i]))
    if pose.pointer is not None:
        pts.append(np.asarray(pose.pointer, float)[None])
        radii.append(np.array([pose.pointer_radius]))
    return np.vstack(pts), np.concatenate(radii)


def prop_extent(spec: RigSpec) -> tuple[np.ndarray, np.ndarray]:
    """(points, radii) of the rig's static props."""
    pts, radii = [np.zeros((0, 3))], [np.zeros(0)]
    for prop in spec.props:
        if prop.shape.kind == "box":
            pts.append(prop_corners(prop))
            radii.append(np.zeros(8))
        else:
            pts.append(np.asarray(prop.position, float)[None])
            radii.append(np.array([prop.shape.radius]))
    return np.vstack(pts), np.concatenate(radii)


def _box_items(cam: Camera, corners: np.ndarray, color: tuple, group: int) -> list[Item]:
    """One painter item per face of a box that faces the eye, Lambert-lit from the eye's side."""
    light = -cam.axes[2] * 0.6 - cam.axes[1] * 0.7 - cam.axes[0] * 0.4
    light /= np.linalg.norm(light)
    centre = corners.mean(axis=0)
    px, depth = cam.project(corners)
    items: list[Item] = []
    for face in _BOX_FACES:
        idx = list(face)
        mid = corners[idx].mean(axis=0)
        normal = mid - centre
        normal /= max(np.linalg.norm(normal), 1e-12)
        if np.dot(normal, cam.eye - mid) <= 0.0:
            continue
        tone = draw.shade(color, draw.lambert(normal, light))
        poly = px[idx]

        def paint(img, poly=poly, tone=tone):
            draw.fill_polygon(img, poly, tone)
            draw.outline(img, poly, draw.shade(tone, 0.6), 1)

        box = np.concatenate((poly.min(axis=0), poly.max(axis=0)))
        plane = (normal, mid)
        items.append(Item(float(depth[idx].mean()), group, paint, box, corners[idx], 0.0, plane))
    return items


def _ball_item(cam: Camera, centre: np.ndarray, r: float, color: tuple, group: int) -> Item:
    centre = np.asarray(centre, float)
    (c,), (z,) = cam.project(centre[None])
    radius = cam.focal * r / max(z, NEAR)
    box = np.concatenate((c - radius, c + radius))
    paint = lambda img: draw.shaded_ball(img, c, radius, color)  # noqa: E731
    return Item(float(z), group, paint, box, centre[None], r)


def _tube_item(cam: Camera, a: np.ndarray, b: np.ndarray, r: float, group: int) -> Item:
    px, z = cam.project(np.array([a, b]))
    ra, rb = (cam.focal * r / max(d, NEAR) for d in z)
    mid_depth = float(cam.project(0.5 * (a + b))[1])
    rmax = max(ra, rb)
    box = np.concatenate((px.min(axis=0) - rmax, px.max(axis=0) + rmax))
    paint = lambda img: draw.shaded_tube(img, px[0], px[1], ra, rb, BONE_COLOR)  # noqa: E731
    return Item(mid_depth, group, paint, box, np.array([a, b]), r)


def _bone_items(cam: Camera, skel: Skeleton, pose: Pose) -> list[Item]:
    """Painter items of every bone shape and joint dot."""
    items: list[Item] = []
    joint_radius = JOINT_RADIUS * figure_factor(skel)
    for i, kind in enumerate(skel.shape):
        head, tail, r = pose.head[i], pose.tail[i], float(skel.radius[i])
        if kind == "capsule":
            items.append(_tube_item(cam, head, tail, r, i))
        elif kind == "sphere":
            items.append(_ball_item(cam, 0.5 * (head + tail), r, BONE_COLOR, i))
        else:
            items.extend(_box_items(cam, bone_box(skel, pose, i), BONE_COLOR, i))
            r = float(np.min(skel.half[i]))
        if skel.parents[i] >= 0:
            # Drawn as if on the bone's surface facing the eye, so its own bone never hides it.
            dot = _ball_item(cam, head, joint_radius, JOINT_COLOR, i)
            items.append(replace(dot, depth=dot.depth - r))
    return items


def draw_items(img: np.ndarray, cam: Camera, skel: Skeleton, pose: Pose, spec: RigSpec) -> None:
    """Bones, joints, props and the pointer, far to near; then the coupling line on top."""
    items = _bone_items(cam, skel, pose)
    for k, prop in enumerate(spec.props):
        group = len(skel.names) + k
        if prop.shape.kind == "box":
            items.extend(_box_items(cam, prop_corners(prop), PROP_COLOR, group))
        else:
            items.append(_ball_item(cam, prop.position, prop.shape.radius, PROP_COLOR, group))
    if pose.pointer is not None:
        group = len(skel.names) + len(spec.props)
        items.append(_ball_item(cam, pose.pointer, pose.pointer_radius, POINTER_COLOR, group))
    for i in paint_order(items):
        items[i].paint(img)
    if pose.pointer is not None and pose.grip is not None:
        px, _ = cam.project(np.array([pose.pointer, pose.grip], dtype=float))
        draw.line(img, px[0], px[1], COUPLING_COLOR, max(1, round(img.shape[0] / 240)))


def _ground_polygon(cam: Camera, corners: np.ndarray) -> np.ndarray | None:
    """Pixels of a world polygon or segment on the ground, clipped at the near plane."""
    clipped = draw.clip_near(cam.to_camera(corners), NEAR)
    if len(clipped) < 2:
        return None
    return cam.focal * clipped[:, :2] / clipped[:, 2:3] + cam.centre


def draw_ground(
    img: np.ndarray, cam: Camera, height: float, bounds: np.ndarray, step: float
) -> None:
    """The ground plane y = ``height`` over ``bounds`` (x0, x1, z0, z1): fill and grid lines
    ``step`` m apart (× 10 while a side would have more than ``MAX_GRID_LINES``)."""
    if not np.all(np.isfinite(bounds)):
        return
    x0, x1, z0, z1 = bounds
    quad = np.array([[x0, height, z0], [x1, height, z0], [x1, height, z1], [x0, height, z1]])
    poly = _ground_polygon(cam, quad)
    if poly is not None and len(poly) >= 3:
        draw.fill_polygon(img, poly, GROUND_COLOR)
    width = max(1, round(img.shape[0] / 480))
    while max(x1 - x0, z1 - z0) > MAX_GRID_LINES * step:
        step *= 10.0
    xs = np.arange(x0, x1 + 1e-9, step)
    zs = np.arange(z0, z1 + 1e-9, step)
    segments = [((x, z0), (x, z1)) for x in xs] + [((x0, z), (x1, z)) for z in zs]
    for (ax, az), (bx, bz) in segments:
        seg = _ground_polygon(cam, np.array([[ax, height, az], [bx, height, bz]]))
        if seg is not None:
            draw.line(img, seg[0], seg[1], GRID_COLOR, width)


def _shadow_pieces(skel: Skeleton, pose: Pose, height: float) -> list[tuple[float, np.ndarray]]:
    """(lowest height above ground, ground outline (n,3)) of every bone piece."""
    pieces = []
    for i, kind in enumerate(skel.shape):
        r = float(skel.radius[i])
        if kind == "box":
            pts = bone_box(skel, pose, i)
            pieces.append((pts[:, 1].min() - height, pts))
            continue
        head, tail = pose.head[i], pose.tail[i]
        if kind == "sphere":
            head = tail = 0.5 * (head + tail)
        ts = np.linspace(0.0, 1.0, SHADOW_PIECES + 1 if kind == "capsule" else 2)
        ends = head + ts[:, None] * (tail - head)
        ring = r * _GROUND_CIRCLE
        for p, q in itertools.pairwise(ends):
            pts = np.vstack((p + ring, q + ring))
            pieces.append((min(p[1], q[1]) - r - height, pts))
    return pieces


def draw_shadows(img: np.ndarray, cam: Camera, skel: Skeleton, pose: Pose, height: float) -> None:
    """Contact shadows: each piece dropped onto the ground, darkest drawn last."""
    shadows = []
    fade = SHADOW_FADE * figure_factor(skel)
    for lift, pts in _shadow_pieces(skel, pose, height):
        strength = SHADOW_DARK * float(np.clip(1.0 - lift / fade, 0.0, 1.0))
        if strength > 0.02:
            flat = pts.copy()
            flat[:, 1] = height
            shadows.append((strength, flat))
    for strength, flat in sorted(shadows, key=lambda s: s[0]):
        cam_pts = cam.to_camera(flat)
        if np.any(cam_pts[:, 2] < NEAR):
            continue  # a shadow reaching behind the eye: skipped rather than drawn wrongly
        px = cam.focal * cam_pts[:, :2] / cam_pts[:, 2:3] + cam.centre
        hull = cv2.convexHull(px.astype(np.float32)).reshape(-1, 2).astype(float)
        draw.fill_polygon(img, hull, draw.shade(GROUND_COLOR, 1.0 - strength))
