"""The renderer's camera: named views, option parsing, and a framing fitted to a set of points.

A view is an azimuth and an elevation (degrees) of the eye around the scene's
centre, and optionally a distance (m).  Azimuth turns about world +y from +z
towards +x; elevation lifts the eye above the horizontal plane.  The eye looks
from ``target + distance · back`` towards ``target``, with

    back  = (cos el · sin az, sin el, cos el · cos az)
    right = (cos az, 0, −sin az)         (screen right, always horizontal)
    up    = back × right                 (screen up)

so the views never roll and ``top`` (el = 90°) keeps +x to the right and −z up.
The doll faces +z: ``front`` (az 0, el 0) sees its face with its left (+x) on
the right of the picture, ``side`` (az 90, el 0) sees its left side, facing the
left edge of the picture.

Projection is a perspective pinhole in OpenCV's camera frame (x right, **y
down**, z forward): ``u = cx + f·x/z, v = cy + f·y/z``.  The distance defaults
to 3 × the radius of the fitted points' bounding sphere (a 2 × 19° field of
view: mild perspective that still shows the ground plane from eye height).
The focal length f and principal point (cx, cy) are chosen so that the fitted
points, padded by their radii, exactly fill the picture minus a margin, and
are centred in it.  One framing is fitted once for a whole set of poses, so
every panel of a contact sheet uses the same camera.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np

from puppetcli.errors import PuppetError, shown

__all__ = ["VIEWS", "Camera", "RenderError", "View", "fit_camera", "parse_size", "parse_view"]

VIEWS = {"front": (0.0, 0.0), "side": (90.0, 0.0), "top": (0.0, 90.0), "iso": (45.0, 30.0)}
DISTANCE_FACTOR = 3.0  # default eye distance in bounding-sphere radii
MARGIN = 0.06  # fraction of the picture's smaller side left empty around the fitted points
NEAR = 1e-3  # m: nearest depth drawn (geometry closer than this is clipped)
MAX_SIZE = 8192  # px: largest accepted panel side


class RenderError(PuppetError):
    """A render cannot be made: bad options, inputs or an unavailable codec."""


@dataclass(frozen=True)
class View:
    """Where the eye is: azimuth and elevation (degrees), distance (m; None = fitted)."""

    azimuth: float
    elevation: float
    distance: float | None = None
    name: str = "custom"


def parse_view(text: str) -> View:
    """``front``, ``side``, ``top``, ``iso`` or ``custom:AZ,EL[,DIST]`` (degrees, m)."""
    name = text.strip().lower()
    if name in VIEWS:
        return View(*VIEWS[name], name=name)
    expected = f"one of {', '.join(VIEWS)} or custom:AZIMUTH,ELEVATION[,DISTANCE]"
    if not name.startswith("custom:"):
        raise RenderError(f"--view: expected {expected}, got {shown(text)}")
    parts = name[len("custom:") :].split(",")
    try:
        values = [float(p) for p in parts]
    except ValueError:
        values = []
    if len(values) not in (2, 3) or not all(math.isfinite(v) for v in values):
        raise RenderError(f"--view: expected {expected} (numbers), got {shown(text)}")
    if not -90.0 <= values[1] <= 90.0:
        raise RenderError(f"--view: expected an elevation in [-90, 90] degrees, got {values[1]:g}")
    if not -360.0 <= values[0] <= 360.0:
        raise RenderError(f"--view: expected an azimuth in [-360, 360] degrees, got {values[0]:g}")
    if len(values) == 3 and not 0.0 < values[2] <= 1e4:
        raise RenderError(f"--view: expected a distance in (0, 1e4] m, got {values[2]:g}")
    return View(values[0], values[1], values[2] if len(values) == 3 else None)


def parse_size(text: str) -> tuple[int, int]:
    """``WxH`` in pixels, e.g. ``480x480``; each side 16 … 8192."""
    match = re.fullmatch(r"\s*(\d+)\s*[xX×]\s*(\d+)\s*", text)
    if not match:
        raise RenderError(
            f"--size: expected WIDTHxHEIGHT in pixels (e.g. 480x480), got {shown(text)}"
        )
    w, h = int(match.group(1)), int(match.group(2))
    if not (16 <= w <= MAX_SIZE and 16 <= h <= MAX_SIZE):
        raise RenderError(f"--size: expected each side in 16 … {MAX_SIZE} px, got {w}x{h}")
    return w, h


def view_axes(view: View) -> np.ndarray:
    """(3, 3) rows: the camera's x (right), y (down), z (forward) axes in the world."""
    az, el = math.radians(view.azimuth), math.radians(view.elevation)
    back = np.array([math.cos(el) * math.sin(az), math.sin(el), math.cos(el) * math.cos(az)])
    right = np.array([math.cos(az), 0.0, -math.sin(az)])
    up = np.cross(back, right)
    return np.array([right, -up, -back])


@dataclass(frozen=True)
class Camera:
    """A pinhole camera: world → camera ``x_c = axes · (p − eye)``; pixels ``f·x/z + c``.

    axes (3, 3): rows right, down, forward (OpenCV frame); eye (3,) m; focal (px);
    centre (2,) principal point (px); size (width, height) px.
    """

    axes: np.ndarray
    eye: np.ndarray
    focal: float
    centre: np.ndarray
    size: tuple[int, int]

    def to_camera(self, points: np.ndarray) -> np.ndarray:
        """World points (..., 3) in the camera frame (..., 3), m."""
        return (np.asarray(points, dtype=float) - self.eye) @ self.axes.T

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(pixels (..., 2), depth (...) m along the view axis) of world points."""
        cam = self.to_camera(points)
        depth = cam[..., 2]
        safe = np.maximum(depth, NEAR)
        return self.focal * cam[..., :2] / safe[..., None] + self.centre, depth

    def scaled(self, factor: float) -> Camera:
        """The same view drawn ``factor`` times larger (for supersampling).

        Pixel centres sit at integer coordinates, so pixel i of this picture,
        area-averaged over the ``factor`` × ``factor`` block it covers in the larger
        one, is centred at factor·i + (factor − 1)/2 there.
        """
        w, h = self.size
        centre = self.centre * factor + 0.5 * (factor - 1)
        return Camera(
            self.axes, self.eye, self.focal * factor, centre, (round(w * factor), round(h * factor))
        )


def fit_camera(view: View, points: np.ndarray, radii: np.ndarray, size: tuple[int, int]) -> Camera:
    """The camera of ``view`` whose picture of ``size`` just holds the points padded by radii."""
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    radii = np.broadcast_to(np.asarray(radii, dtype=float), points.shape[:1])
    lo, hi = points.min(axis=0), points.max(axis=0)
    target = 0.5 * (lo + hi)
    sphere = float(np.max(np.linalg.norm(points - target, axis=1) + radii))
    sphere = max(sphere, 1e-3)
    distance = view.distance if view.distance is not None else DISTANCE_FACTOR * sphere
    if distance <= 1.05 * sphere:
        raise RenderError(
            f"--view: distance {distance:g} m puts the eye inside the scene "
            f"(expected more than {1.05 * sphere:.2f} m)"
        )
    axes = view_axes(view)
    eye = target - distance * axes[2]
    cam = (points - eye) @ axes.T
    xy = cam[:, :2] / cam[:, 2:3]
    pad = (radii / cam[:, 2])[:, None]
    lo2, hi2 = (xy - pad).min(axis=0), (xy + pad).max(axis=0)
    w, h = size
    margin = MARGIN * min(w, h)
    extent = np.maximum(hi2 - lo2, 1e-9)
    focal = float(min((w - 2 * margin) / extent[0], (h - 2 * margin) / extent[1]))
    # Pixel centres are at integers, so the picture's middle is at ((w − 1)/2, (h − 1)/2).
    centre = 0.5 * np.array([w - 1.0, h - 1.0]) - focal * 0.5 * (lo2 + hi2)
    return Camera(axes, eye, focal, centre, (w, h))
