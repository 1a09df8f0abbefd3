"""Pictures of poses with OpenCV, off-screen and deterministic: panels, contact sheets, key PNGs.

A picture shows the ground grid with the bones' contact shadows, the static
props, the bones as shaded capsules, spheres and boxes drawn far to near,
joints as dots, optionally the haptic pointer and its coupling line, and the
key's label and time.  The camera and its conventions are in
``puppetcli.render.camera``; scene content in ``puppetcli.render.scene``.

One :class:`Framing` (camera and ground extent) is fitted to *all* the poses
of a call, so the panels of a contact sheet compare directly.  Pictures are
drawn at ``SUPERSAMPLE`` × the size and reduced with area averaging, then the
text is written.  No randomness and no clock: the same input gives the same
bytes (PNG via ``cv2.imencode``, written atomically).

Used by ``puppetcli render`` and by ``puppetcli pose`` through :func:`render_keys`.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from puppetcli.outputs import atomic_path
from puppetcli.render.camera import Camera, RenderError, View, fit_camera, parse_view
from puppetcli.render.scene import (
    GRID_MARGIN,
    GRID_STEP,
    Pose,
    draw_ground,
    draw_items,
    draw_shadows,
    figure_factor,
    grid_step,
    pose_extent,
    prop_extent,
)
from puppetcli.rig.skeleton import Skeleton, key_pose
from puppetcli.run.keyframes import Keyframe
from solver.spec import RigSpec

__all__ = [
    "Framing",
    "Pose",
    "RenderError",
    "contact_sheet",
    "default_cols",
    "frame_poses",
    "poses_from_keys",
    "render_keys",
    "render_pose",
    "write_png",
]

SUPERSAMPLE = 2
BACKGROUND = (246, 242, 238)  # BGR
TEXT_COLOR = (40, 40, 40)
BORDER_COLOR = (170, 170, 170)
_KEY_PNG = re.compile(r"\d{3,}\.png")


@dataclass(frozen=True)
class Framing:
    """The fixed picture set-up of one call: camera, ground height (None = no ground), the
    ground grid's extent (x0, x1, z0, z1) and its step, in m."""

    camera: Camera
    ground: float | None
    bounds: np.ndarray
    step: float = GRID_STEP


def frame_poses(
    skel: Skeleton,
    poses: Sequence[Pose],
    spec: RigSpec,
    view: View | str = "iso",
    size: tuple[int, int] = (480, 480),
) -> Framing:
    """The framing that shows every pose, the props and the bones' ground shadows."""
    if not poses:
        raise RenderError("nothing to render: no poses")
    view = parse_view(view) if isinstance(view, str) else view
    parts = [pose_extent(skel, p) for p in poses] + [prop_extent(spec)]
    points = np.vstack([p for p, _ in parts])
    radii = np.concatenate([r for _, r in parts])
    ground = spec.ground.height if spec.ground is not None else None
    if ground is not None:
        shadow = points.copy()
        shadow[:, 1] = ground
        points, radii = np.vstack((points, shadow)), np.concatenate((radii, radii))
    margin, step = GRID_MARGIN * figure_factor(skel), grid_step(skel)
    lo, hi = points.min(axis=0) - margin, points.max(axis=0) + margin
    bounds = np.array(
        [
            math.floor(lo[0] / step) * step,
            math.ceil(hi[0] / step) * step,
            math.floor(lo[2] / step) * step,
            math.ceil(hi[2] / step) * step,
        ]
    )
    return Framing(fit_camera(view, points, radii, size), ground, bounds, step)


def _caption(img: np.ndarray, pose: Pose) -> None:
    """The label at the top left and the time at the bottom left."""
    h = img.shape[0]
    scale = max(0.3, 0.55 * h / 480)
    pad = max(2, round(h / 60))
    font = cv2.FONT_HERSHEY_SIMPLEX
    (_, th), _ = cv2.getTextSize("Ag", font, scale, 1)
    if pose.label:
        cv2.putText(img, pose.label, (pad, pad + th), font, scale, TEXT_COLOR, 1, cv2.LINE_AA)
    cv2.putText(img, f"t = {pose.time:.3f} s", (pad, h - pad), font, scale, TEXT_COLOR, 1,
                cv2.LINE_AA)  # fmt: skip


def render_pose(
    skel: Skeleton, pose: Pose, spec: RigSpec, framing: Framing, caption: bool = True
) -> np.ndarray:
    """A BGR picture (H, W, 3) uint8 of ``pose`` with ``framing``'s camera."""
    cam = framing.camera.scaled(SUPERSAMPLE)
    w, h = cam.size
    img = np.empty((h, w, 3), np.uint8)
    img[:] = BACKGROUND
    if framing.ground is not None:
        draw_ground(img, cam, framing.ground, framing.bounds, framing.step)
        draw_shadows(img, cam, skel, pose, framing.ground)
    draw_items(img, cam, skel, pose, spec)
    img = cv2.resize(img, framing.camera.size, interpolation=cv2.INTER_AREA)
    if caption:
        _caption(img, pose)
    return img


def default_cols(n: int) -> int:
    """Columns of a contact sheet of ``n`` panels: one row up to 4, then about square."""
    return max(1, min(n, max(4, math.ceil(math.sqrt(n)))))


def contact_sheet(panels: Sequence[np.ndarray], cols: int) -> np.ndarray:
    """Panels (all one size) in a grid of ``cols`` columns and ceil(n / cols) rows, row-major;
    each panel keeps its size, with a one-pixel border on its right and bottom edges."""
    if not panels:
        raise RenderError("nothing to render: no panels")
    if cols < 1:
        raise RenderError(f"--cols: expected a positive number of columns, got {cols}")
    cols = min(cols, len(panels))
    h, w = panels[0].shape[:2]
    rows = math.ceil(len(panels) / cols)
    sheet = np.empty((rows * h, cols * w, 3), np.uint8)
    sheet[:] = BACKGROUND
    for i, panel in enumerate(panels):
        r, c = divmod(i, cols)
        sheet[r * h : (r + 1) * h, c * w : (c + 1) * w] = panel
    for c in range(1, cols + 1):
        sheet[:, c * w - 1] = BORDER_COLOR
    for r in range(1, rows + 1):
        sheet[r * h - 1, :] = BORDER_COLOR
    return sheet


def poses_from_keys(skel: Skeleton, keys: Sequence[Keyframe]) -> list[Pose]:
    """The pose of every key (bone poses from ``key_pose``), labelled with its label and time."""
    poses = []
    for i, key in enumerate(keys):
        missing = [name for name in skel.names if name not in key.bones]
        if missing:
            raise RenderError(
                f"key {i} ({key.label!r}): expected a pose of every bone of the rig, "
                f"got no bone {missing[0]!r}"
            )
        head, tail, rot = key_pose(skel, key)
        poses.append(Pose(head, tail, rot, key.label, key.time))
    return poses


def write_png(path: Path, img: np.ndarray) -> None:
    """Write ``img`` as a PNG atomically (encoded in memory, then temporary file and rename)."""
    ok, data = cv2.imencode(".png", img)
    if not ok:
        raise RenderError(f"{path}: cannot encode a PNG")
    try:
        with atomic_path(Path(path)) as tmp:
            tmp.write_bytes(data.tobytes())
    except OSError as exc:
        raise RenderError(f"{path}: cannot write: {exc.strerror or exc}") from exc


def render_keys(
    outdir: Path,
    skel: Skeleton,
    keys: list[Keyframe],
    spec: RigSpec,
    view: str = "iso",
    size: tuple[int, int] = (480, 480),
) -> None:
    """Write ``outdir/keys/001.png`` … (one per key, in key order) and ``outdir/sheet.png``.

    All pictures share one framing.  Numbered PNGs in ``outdir/keys`` beyond the
    last key (left by an earlier run with more keys) are removed, so the folder
    matches the keys.  Existing files are overwritten: the caller applies the
    output policy (``--force``).  Every picture is drawn before the first is written.
    """
    poses = poses_from_keys(skel, keys)
    framing = frame_poses(skel, poses, spec, view, size)
    panels = [render_pose(skel, pose, spec, framing) for pose in poses]
    keydir = Path(outdir) / "keys"
    try:
        keydir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise RenderError(f"{keydir}: cannot create directory: {exc.strerror}") from exc
    names = [f"{i:03d}.png" for i in range(1, len(panels) + 1)]
    sheet = contact_sheet(panels, default_cols(len(panels)))
    for name, panel in zip(names, panels, strict=True):
        write_png(keydir / name, panel)
    remove_stale_keys(keydir, names)
    write_png(Path(outdir) / "sheet.png", sheet)


def remove_stale_keys(keydir: Path, names: list[str]) -> None:
    """Remove numbered PNGs in ``keydir`` that are not among ``names`` (an earlier run's)."""
    for stale in sorted(keydir.iterdir()):
        if _KEY_PNG.fullmatch(stale.name) and stale.name not in names:
            stale.unlink()
