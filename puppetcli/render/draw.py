"""OpenCV drawing primitives of the renderer: shaded tubes and balls, lit polygons, clipped lines.

Everything is drawn with sub-pixel fixed-point coordinates (``shift`` = 4 bits)
and ``LINE_AA``, on a BGR ``uint8`` picture.  Round shapes are shaded without a
depth buffer: a tube (the picture of a capsule, a convex hull of its two end
circles) or a ball is filled in a few nested layers, each smaller, brighter and
shifted towards the light, which reads as a lit cylinder or sphere.  Flat faces
get Lambert shading from their world normal.  Coordinates come in as float
pixels; nothing here knows about the world or the camera.
"""

from __future__ import annotations

import cv2
import numpy as np

__all__ = [
    "LIGHT_2D",
    "clip_near",
    "fill_polygon",
    "lambert",
    "line",
    "shaded_ball",
    "shaded_tube",
]

SHIFT = 4  # fractional bits of the fixed-point pixel coordinates given to OpenCV
_ONE = 1 << SHIFT
# Screen direction towards the light (up and to the left), unit length.
LIGHT_2D = np.array([-0.45, -0.89]) / np.hypot(0.45, 0.89)
# (radius fraction, brightness) of the nested layers of a round shape, outermost first.
LAYERS = ((1.0, 0.55), (0.88, 0.75), (0.7, 0.9), (0.45, 1.02), (0.2, 1.12))
LAYER_SHIFT = 0.5  # how far (in radii) the innermost layer moves towards the light
CIRCLE = np.stack(
    (np.cos(np.linspace(0, 2 * np.pi, 24, endpoint=False)),
     np.sin(np.linspace(0, 2 * np.pi, 24, endpoint=False))), axis=1,
)  # fmt: skip


def _fixed(points: np.ndarray) -> np.ndarray:
    """Float pixels (n, 2) as OpenCV fixed-point int32 (n, 1, 2)."""
    return np.round(np.asarray(points, dtype=float) * _ONE).astype(np.int32).reshape(-1, 1, 2)


def shade(color: tuple[int, int, int], brightness: float) -> tuple[int, int, int]:
    """``color`` scaled by ``brightness`` (clipped to 0 … 255)."""
    return tuple(min(max(round(c * brightness), 0), 255) for c in color)  # type: ignore[return-value]


def fill_polygon(img: np.ndarray, points: np.ndarray, color: tuple[int, int, int]) -> None:
    """Fill the polygon of float pixel ``points`` (n, 2), n ≥ 3, anti-aliased."""
    if len(points) >= 3 and np.all(np.isfinite(points)):
        cv2.fillPoly(img, [_fixed(points)], color, cv2.LINE_AA, SHIFT)


def outline(img: np.ndarray, points: np.ndarray, color: tuple[int, int, int], width: int) -> None:
    """The closed outline of a polygon of float pixel ``points``."""
    if len(points) >= 2 and np.all(np.isfinite(points)):
        cv2.polylines(img, [_fixed(points)], True, color, width, cv2.LINE_AA, SHIFT)


def line(img: np.ndarray, a: np.ndarray, b: np.ndarray, color: tuple, width: int) -> None:
    """An anti-aliased segment between float pixels ``a`` and ``b``."""
    pa, pb = _fixed(a).reshape(2), _fixed(b).reshape(2)
    cv2.line(img, tuple(int(v) for v in pa), tuple(int(v) for v in pb), color, width,
             cv2.LINE_AA, SHIFT)  # fmt: skip


def _hull(a: np.ndarray, b: np.ndarray, ra: float, rb: float) -> np.ndarray:
    """Convex hull (n, 2) of the circles (a, ra) and (b, rb) in pixels."""
    pts = np.vstack((a + ra * CIRCLE, b + rb * CIRCLE)).astype(np.float32)
    return cv2.convexHull(pts).reshape(-1, 2).astype(float)


def shaded_tube(
    img: np.ndarray,
    a: np.ndarray,
    b: np.ndarray,
    ra: float,
    rb: float,
    color: tuple[int, int, int],
    rim: int = 1,
) -> None:
    """A lit capsule seen in perspective: ends ``a``, ``b`` (px) with radii ``ra``, ``rb`` (px)."""
    if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
        return
    for k, (frac, brightness) in enumerate(LAYERS):
        move = (1.0 - frac) * LAYER_SHIFT / (1.0 - LAYERS[-1][0]) * LIGHT_2D
        hull = _hull(a + move * ra, b + move * rb, frac * ra, frac * rb)
        fill_polygon(img, hull, shade(color, brightness))
        if k == 0 and rim:
            outline(img, hull, shade(color, 0.35), rim)


def shaded_ball(
    img: np.ndarray, c: np.ndarray, r: float, color: tuple[int, int, int], rim: int = 1
) -> None:
    """A lit sphere of centre ``c`` and radius ``r`` (px)."""
    shaded_tube(img, c, c, r, r, color, rim)


def lambert(normal: np.ndarray, light: np.ndarray) -> float:
    """Brightness of a face with unit ``normal`` under the unit direction to the ``light``."""
    return 0.5 + 0.6 * max(0.0, float(np.dot(normal, light)))


def clip_near(cam: np.ndarray, near: float) -> np.ndarray:
    """Clip a polygon or segment (n, 3) in camera coordinates to depth z ≥ ``near``.

    Sutherland–Hodgman against one plane; a segment (n = 2) stays a segment.
    Returns the clipped vertices (possibly none).
    """
    out: list[np.ndarray] = []
    n = len(cam)
    edges = range(n) if n > 2 else range(1)
    for i in edges:
        p, q = cam[i], cam[(i + 1) % n]
        p_in, q_in = p[2] >= near, q[2] >= near
        if p_in:
            out.append(p)
        if p_in != q_in:
            t = (near - p[2]) / (q[2] - p[2])
            out.append(p + t * (q - p))
        if n == 2 and q_in:
            out.append(q)
    return np.array(out).reshape(-1, 3)
