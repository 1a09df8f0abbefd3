"""Rendered pixels checked against geometry computed without the renderer.

Points of the doll are projected with the framing's camera (itself checked
against cv2.projectPoints in test_render_camera.py) and the picture must show
wood there; points known to be empty must show no wood.  Symmetry and extents
of the T-pose follow from the rig alone.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_render_fixtures import doll, doll_mask, key

from puppetcli.render.picture import Pose, frame_poses, poses_from_keys, render_pose
from puppetcli.render.scene import GROUND_COLOR
from puppetcli.rig.load import rig_from_text
from puppetcli.rig.skeleton import Skeleton

SIZE = (160, 160)


def _picture(
    view: str, arm_deg: float = 0.0, props: bool = False, also: float | None = None, size=SIZE
):
    """(picture, framing, skeleton) of the doll with the left arm raised ``arm_deg``; the
    framing also holds the pose raised ``also`` degrees when given."""
    spec, skel = doll(props)
    angles = [arm_deg] if also is None else [arm_deg, also]
    poses = poses_from_keys(skel, [key(skel, a) for a in angles])
    framing = frame_poses(skel, poses, spec, view, size)
    return render_pose(skel, poses[0], spec, framing, caption=False), framing, skel


def _pixel(framing, point) -> tuple[int, int]:
    (u, v), _ = framing.camera.project(np.asarray(point, float))
    return round(float(v)), round(float(u))


@pytest.mark.parametrize("view", ["front", "side", "iso"])
def test_head_top_is_drawn_and_empty_space_is_not(view: str) -> None:
    img, framing, skel = _picture(view)
    mask = doll_mask(img)
    head_top = skel.tail0[skel.names.index("head")] + [0.0, 0.085 - 0.01, 0.0]  # 1 cm inside
    assert mask[_pixel(framing, head_top)]
    above_left_hand = [0.6, 1.65, 0.0]  # above the arm, beside the head: nothing there
    r, c = _pixel(framing, above_left_hand)
    assert not mask[max(0, r - 1) : r + 2, max(0, c - 1) : c + 2].any()


def test_front_view_shows_the_left_arm_on_the_right() -> None:
    """Raising the doll's left (+x) arm changes the right half of a front view only."""
    rest, framing, _ = _picture("front", 0.0, also=60.0)
    raised, same, _ = _picture("front", 60.0, also=0.0)
    assert np.array_equal(same.camera.eye, framing.camera.eye)
    changed = np.any(doll_mask(rest) != doll_mask(raised), axis=0)
    centre = round(float(framing.camera.project(np.array([0.0, 1.0, 0.0]))[0][0]))
    assert changed[centre + 5 :].sum() > 20
    assert changed[: centre - 5].sum() == 0


def test_front_view_of_the_t_pose_is_mirror_symmetric() -> None:
    """Shape symmetric to the pixel.  Shading is lit from the upper left, so the grey levels
    of the mirror image differ a little, and the silhouette by some anti-aliased edge pixels
    (a dark rim on the right against a lit one on the left), about 3 % of the doll."""
    img, framing, _ = _picture("front")
    centre_u = float(framing.camera.project(np.array([0.0, 1.0, 0.0]))[0][0])
    assert centre_u == pytest.approx((SIZE[0] - 1) / 2, abs=1e-9)  # the doll is centred
    mask = doll_mask(img)
    assert mask.sum() > 1500
    assert (mask != mask[:, ::-1]).sum() < 0.05 * mask.sum()
    grey = img.astype(int).sum(axis=2) / 3
    assert np.abs(grey - grey[:, ::-1]).mean() < 3.0
    raised, _, _ = _picture("front", 45.0)  # the test can fail: an asymmetric pose
    mask = doll_mask(raised)
    assert (mask != mask[:, ::-1]).sum() > 0.1 * mask.sum()


def test_top_view_widest_extent_is_the_arm_span() -> None:
    img, framing, skel = _picture("top")
    mask = doll_mask(img)
    cols = np.flatnonzero(mask.any(axis=0))
    rows = np.flatnonzero(mask.any(axis=1))
    assert np.ptp(cols) > 2 * np.ptp(rows)  # arms across, the body's depth along the rows
    hand = skel.names.index("hand_l"), skel.names.index("hand_r")
    tips = [skel.tail0[i] + np.sign(skel.tail0[i][0]) * np.array([0.03, 0.0, 0.0]) for i in hand]
    (_, c_left), (_, c_right) = (_pixel(framing, p) for p in tips)
    assert abs(cols.max() - c_left) <= 2 and abs(cols.min() - c_right) <= 2
    widest_row = int(np.argmax(mask.sum(axis=1)))
    arm_row, _ = _pixel(framing, skel.tail0[skel.names.index("forearm_l")])
    assert abs(widest_row - arm_row) <= 4


def test_side_view_sees_the_feet_pointing_left() -> None:
    """From +x the doll faces +z, which is the picture's left: the toes are left of the heels."""
    img, framing, skel = _picture("side")
    foot = skel.names.index("foot_l")
    (_, heel), (_, toe) = (_pixel(framing, p) for p in (skel.head0[foot], skel.tail0[foot]))
    assert toe < heel - 5
    assert doll_mask(img)[_pixel(framing, skel.tail0[foot])]


def test_ground_grid_and_contact_shadow() -> None:
    """The ground is drawn under the doll; the ground under a foot (1 cm up), where not hidden
    by the doll, is darkened; under the hands (1.36 m up, beyond the fade height) it is not."""
    img, framing, skel = _picture("iso", size=(400, 400))
    ground = np.all(np.abs(img.astype(int) - GROUND_COLOR) <= 2, axis=2)
    assert ground.mean() > 0.1
    mask = doll_mask(img)
    for name, dark in (("foot_r", True), ("foot_l", True), ("hand_l", False)):
        i = skel.names.index(name)
        footprint = _footprint(framing, skel.head0[i], skel.tail0[i], 0.7 * skel.radius[i])
        visible = [p for p in footprint if not mask[p]]
        assert len(visible) >= 5
        levels = np.array([img[p] for p in visible], int)
        darkening = np.array(GROUND_COLOR) - np.median(levels, axis=0)  # median: past grid lines
        assert np.all(darkening > 40) if dark else np.all(np.abs(darkening) < 5)


def _footprint(framing, head: np.ndarray, tail: np.ndarray, r: float) -> list[tuple[int, int]]:
    """Pixels of ground points within ``r`` of the bone's axis seen from above."""
    xs = np.linspace(-1.0, 1.0, 201)
    grid = np.array([[x, 0.0, z] for x in xs for z in xs])
    a, b = head * [1, 0, 1], tail * [1, 0, 1]
    t = np.clip((grid - a) @ (b - a) / max(np.dot(b - a, b - a), 1e-12), 0.0, 1.0)
    near = np.linalg.norm(grid - (a + t[:, None] * (b - a)), axis=1) < r
    return sorted({_pixel(framing, p) for p in grid[near]})


SHAPES_RIG = """\
name: shapes
ground: {height: 0.0}
bones:
  - {name: base, head: [0, 0.5, 0], tail: [0, 0.5, 0.6], shape: {type: box, size: [0.1, 0.6, 0.2]}}
  - {name: ball, parent: base, head: [0, 0.5, 0.6], tail: [0.6, 0.5, 0.6],
     shape: {type: sphere, radius: 0.15}}
props:
  - {name: globe, shape: {type: sphere, radius: 0.1}, position: [-0.5, 0.1, 0.0]}
  - {name: slab, shape: {type: box, size: [0.4, 0.1, 0.2]}, position: [0.5, 0.05, -0.4],
     rotation: {axis: [0, 1, 0], angle: 90}}
"""


def test_spheres_boxes_and_props_from_the_top() -> None:
    """Seen from +y: the box bone lies along z (its local y runs head → tail), the sphere bone
    sits at its head–tail midpoint, the sphere prop at its position, the rotated slab along z."""
    spec = rig_from_text(SHAPES_RIG, "shapes.yaml")
    skel = Skeleton.from_spec(spec)
    pose = Pose(skel.head0, skel.tail0, np.tile([1.0, 0, 0, 0], (2, 1)))
    framing = frame_poses(skel, [pose], spec, "top", (200, 200))
    img = render_pose(skel, pose, spec, framing, caption=False)
    wood, blue = doll_mask(img), img[..., 0].astype(int) - img[..., 2] > 15
    assert wood[_pixel(framing, [0.0, 0.55, 0.55])]  # the box's far end along z
    assert not wood[_pixel(framing, [0.12, 0.55, 0.3])]  # 0.05 m half width: empty beside it
    assert wood[_pixel(framing, [0.3 + 0.1, 0.5, 0.6])] and wood[_pixel(framing, [0.3, 0.5, 0.7])]
    assert not wood[_pixel(framing, [0.3 + 0.2, 0.5, 0.6])]
    assert blue[_pixel(framing, [-0.5, 0.2, 0.05])] and blue[_pixel(framing, [0.5, 0.1, -0.25])]
    assert not blue[_pixel(framing, [0.65, 0.1, -0.4])]  # the slab is 0.2 wide along x now
