"""The renderer's camera: option parsing, view directions, projection against OpenCV, framing."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from puppetcli.render.camera import RenderError, View, fit_camera, parse_size, parse_view


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("front", (0.0, 0.0, None)),
        ("SIDE", (90.0, 0.0, None)),
        ("top", (0.0, 90.0, None)),
        ("iso", (45.0, 30.0, None)),
        ("custom:30,20,3.5", (30.0, 20.0, 3.5)),
        ("custom:-120,-10", (-120.0, -10.0, None)),
    ],
)
def test_parse_view(text: str, expected: tuple) -> None:
    view = parse_view(text)
    assert (view.azimuth, view.elevation, view.distance) == expected


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("back", "expected one of front, side, top, iso or custom:"),
        ("custom:30", "(numbers), got 'custom:30'"),
        ("custom:a,b", "(numbers)"),
        ("custom:1,2,3,4", "(numbers)"),
        ("custom:0,95", "elevation in [-90, 90] degrees, got 95"),
        ("custom:0,10,-2", "distance in (0, 1e4] m, got -2"),
        ("custom:0,10,2e4", "distance in (0, 1e4] m, got 20000"),
        ("custom:400,10", "azimuth in [-360, 360] degrees, got 400"),
        ("custom:0,nan", "(numbers)"),
    ],
)
def test_parse_view_errors(text: str, message: str) -> None:
    with pytest.raises(RenderError, match=r"^--view: ") as info:
        parse_view(text)
    assert message in str(info.value)


def test_parse_size() -> None:
    assert parse_size("480x320") == (480, 320)
    assert parse_size(" 96X96 ") == (96, 96)
    for bad in ("480", "480x", "0x10", "10x10", "x", "-5x5", "99999x100", "4.5x8"):
        with pytest.raises(RenderError, match=r"^--size: expected"):
            parse_size(bad)


# Eye direction (from the scene centre towards the eye) of each named view, and the world
# direction that must appear to the right in the picture: stated, not computed.
EXPECTED_AXES = {
    "front": ([0, 0, 1], [1, 0, 0]),
    "side": ([1, 0, 0], [0, 0, -1]),
    "top": ([0, 1, 0], [1, 0, 0]),
    "iso": ([math.sqrt(0.375), 0.5, math.sqrt(0.375)], [math.sqrt(0.5), 0, -math.sqrt(0.5)]),
}
POINTS = np.array([[-0.8, 0.0, -0.2], [0.8, 1.7, 0.2], [0.1, 0.9, 0.0]])


@pytest.mark.parametrize("name", list(EXPECTED_AXES))
def test_named_views_look_from_the_documented_side(name: str) -> None:
    cam = fit_camera(parse_view(name), POINTS, np.zeros(3), (200, 100))
    back, right = (np.array(v, float) for v in EXPECTED_AXES[name])
    target = 0.5 * (POINTS.min(axis=0) + POINTS.max(axis=0))
    towards_eye = (cam.eye - target) / np.linalg.norm(cam.eye - target)
    assert np.allclose(towards_eye, back, atol=1e-12)
    # A step to the right in the world moves the picture point to the right (u grows).
    (u0, v0), (u1, v1) = cam.project(np.array([target, target + 0.01 * right]))[0]
    assert u1 > u0 and abs(v1 - v0) < 1e-6 * abs(u1 - u0) + 1e-9
    # World up (or −z seen from the top) moves the picture point up: v (y down) shrinks.
    up = np.array([0.0, 0.0, -1.0]) if name == "top" else np.array([0.0, 1.0, 0.0])
    assert cam.project(target + 0.01 * up)[0][1] < v0


@pytest.mark.parametrize("view", ["front", "side", "top", "iso", "custom:-35,-20,6"])
def test_projection_matches_opencv(view: str) -> None:
    """Our pinhole equals cv2.projectPoints with the same extrinsics and intrinsics."""
    cam = fit_camera(parse_view(view), POINTS, np.full(3, 0.05), (320, 240))
    rng = np.random.default_rng(7)
    world = rng.uniform(-1.0, 1.0, (50, 3)) + [0.0, 0.9, 0.0]
    rvec, _ = cv2.Rodrigues(cam.axes)
    tvec = -cam.axes @ cam.eye
    k = np.array([[cam.focal, 0, cam.centre[0]], [0, cam.focal, cam.centre[1]], [0, 0, 1]])
    expected, _ = cv2.projectPoints(world, rvec, tvec, k, np.zeros(5))
    ours, depth = cam.project(world)
    assert np.all(depth > 0)
    assert np.allclose(ours, expected.reshape(-1, 2), atol=1e-6)


@pytest.mark.parametrize("view", ["front", "side", "top", "iso", "custom:200,45"])
def test_fit_fills_the_picture_minus_the_margin(view: str) -> None:
    """Padded points touch the margin on the limiting axis and stay inside on the other."""
    w, h = 300, 200
    radii = np.array([0.05, 0.1, 0.0])
    cam = fit_camera(parse_view(view), POINTS, radii, (w, h))
    cam_pts = cam.to_camera(POINTS)
    px, depth = cam.project(POINTS)
    pad = (cam.focal * radii / depth)[:, None]
    lo, hi = (px - pad).min(axis=0), (px + pad).max(axis=0)
    margin = 0.06 * min(w, h) - 0.5  # from the picture's edge to the first pixel centre
    far = np.array([w - 1 - margin, h - 1 - margin])
    assert np.all(lo >= margin - 1e-6) and np.all(hi <= far + 1e-6)
    touching = np.isclose(lo, margin) & np.isclose(hi, far)
    assert touching.any()
    assert np.allclose(0.5 * (lo + hi), [(w - 1) / 2, (h - 1) / 2])  # centred on pixel centres
    assert np.all(cam_pts[:, 2] > 0)


def test_custom_distance_and_eye_inside_the_scene() -> None:
    cam = fit_camera(View(30.0, 20.0, 3.5), POINTS, np.zeros(3), (100, 100))
    target = 0.5 * (POINTS.min(axis=0) + POINTS.max(axis=0))
    assert np.linalg.norm(cam.eye - target) == pytest.approx(3.5)
    with pytest.raises(RenderError, match="puts the eye inside the scene"):
        fit_camera(View(30.0, 20.0, 0.5), POINTS, np.zeros(3), (100, 100))


def test_supersampled_camera_keeps_pixel_centres() -> None:
    """Pixel i of the picture is the mean of pixels 2i, 2i+1 of the doubled one."""
    cam = fit_camera(parse_view("iso"), POINTS, np.zeros(3), (64, 48))
    big = cam.scaled(2)
    assert big.size == (128, 96)
    u, _ = cam.project(POINTS)
    u2, _ = big.project(POINTS)
    assert np.allclose(u2, 2 * u + 0.5)
