"""The work-precision study as a PNG (OpenCV only): error against run time, log-log.

One panel per scene in a 2 × 2 grid (creep, chain-1s, chain-3s, doll; up to four),
one polyline per setting through its steps h (points in time order), and a shared
legend on the right.  Our settings are drawn with filled discs and thick lines, MuJoCo's
(``mujoco-*``, whose errors are against MuJoCo's own reference: the legend says so)
with hollow squares and thin lines.  Points without a measured time or a
finite error (n/a, unstable) are not drawn.  Size: ``PLOT_SIZE`` (height, width).
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from puppetcli.bench.precision_row import BASELINE, PrecisionRow

PANEL_W, PANEL_H, LEGEND_W, MARGIN = 560, 440, 190, 60
PLOT_SIZE = (2 * PANEL_H, 2 * PANEL_W + LEGEND_W)  # (height, width) pixels of the PNG
_GREY, _BLACK = (220, 220, 220), (0, 0, 0)
_FONT = cv2.FONT_HERSHEY_SIMPLEX

_PALETTE = [  # BGR, distinct (tab20-like)
    (180, 119, 31), (14, 127, 255), (44, 160, 44), (40, 39, 214), (189, 103, 148),
    (75, 86, 140), (194, 119, 227), (34, 189, 188), (207, 190, 23), (0, 0, 0),
    (127, 127, 127), (232, 199, 174), (120, 187, 255), (138, 223, 152), (150, 152, 255),
    (213, 176, 197), (148, 156, 196),
]  # fmt: skip


def _colour(i: int) -> tuple[int, int, int]:
    return _PALETTE[i % len(_PALETTE)]


def _is_peer(name: str) -> bool:
    return name.startswith("mujoco")


def _marker(img: np.ndarray, p: tuple[int, int], colour, peer: bool) -> None:
    if peer:
        cv2.rectangle(img, (p[0] - 4, p[1] - 4), (p[0] + 4, p[1] + 4), colour, 2)
    else:
        cv2.circle(img, p, 3, colour, -1, cv2.LINE_AA)


def _decades(values: np.ndarray) -> tuple[int, int]:
    """Whole decades that enclose the values (at least one decade wide)."""
    lo, hi = math.floor(values.min()), math.ceil(values.max())
    return lo, hi if hi > lo else lo + 1


def _axes(img: np.ndarray, box: tuple[int, int, int, int], xr, yr, title: str) -> None:
    left, top, right, bottom = box
    for d in range(xr[0], xr[1] + 1):
        x = round(left + (d - xr[0]) / (xr[1] - xr[0]) * (right - left))
        cv2.line(img, (x, top), (x, bottom), _GREY, 1)
        cv2.putText(img, f"1e{d}", (x - 14, bottom + 18), _FONT, 0.4, _BLACK, 1, cv2.LINE_AA)
    for d in range(yr[0], yr[1] + 1):
        y = round(bottom - (d - yr[0]) / (yr[1] - yr[0]) * (bottom - top))
        cv2.line(img, (left, y), (right, y), _GREY, 1)
        cv2.putText(img, f"1e{d}", (left - MARGIN + 8, y + 4), _FONT, 0.4, _BLACK, 1, cv2.LINE_AA)
    cv2.rectangle(img, (left, top), (right, bottom), _BLACK, 1)
    cv2.putText(img, title, (left, top - 10), _FONT, 0.5, _BLACK, 1, cv2.LINE_AA)
    cv2.putText(img, "run time (s)", (left + 180, bottom + 36), _FONT, 0.45, _BLACK, 1)


def _panel(img: np.ndarray, x0: int, y0: int, rows: list[PrecisionRow], names: list[str]) -> None:
    """One scene's log-log panel: error (y) against seconds (x), one polyline per setting."""
    ok = [r for r in rows if math.isfinite(r.error) and math.isfinite(r.seconds) and r.seconds > 0]
    if not ok:
        return
    xr = _decades(np.log10([r.seconds for r in ok]))
    yr = _decades(np.log10([max(r.error, 1e-16) for r in ok]))
    box = (x0 + MARGIN, y0 + 30, x0 + PANEL_W - 15, y0 + PANEL_H - 45)
    left, top, right, bottom = box

    def px(t: float, e: float) -> tuple[int, int]:
        u = (math.log10(t) - xr[0]) / (xr[1] - xr[0])
        v = (math.log10(max(e, 1e-16)) - yr[0]) / (yr[1] - yr[0])
        return round(left + u * (right - left)), round(bottom - v * (bottom - top))

    _axes(img, box, xr, yr, f"{ok[0].scene}: error ({ok[0].unit}) vs run time (s)")
    for i, name in enumerate(names):
        pts = [px(t, e) for t, e in sorted((r.seconds, r.error) for r in ok if r.setting == name)]
        if not pts:
            continue
        peer = _is_peer(name)
        xy = np.array(pts, dtype=np.int32).reshape(-1, 1, 2)
        cv2.polylines(img, [xy], False, _colour(i), 1 if peer else 2, cv2.LINE_AA)
        for p in pts:
            _marker(img, p, _colour(i), peer)


def plot_png(rows: list[PrecisionRow]) -> bytes:
    """The study as a PNG of PLOT_SIZE: a panel per scene (up to four), a shared legend."""
    img = np.full((*PLOT_SIZE, 3), 255, dtype=np.uint8)
    names = list(dict.fromkeys(r.setting for r in rows))
    for k, scene in enumerate(list(dict.fromkeys(r.scene for r in rows))[:4]):
        x0, y0 = (k % 2) * PANEL_W, (k // 2) * PANEL_H
        _panel(img, x0, y0, [r for r in rows if r.scene == scene], names)
    x = 2 * PANEL_W + 5
    for i, name in enumerate(names):
        y = 40 + 22 * i
        cv2.line(img, (x, y), (x + 25, y), _colour(i), 1 if _is_peer(name) else 3)
        _marker(img, (x + 12, y), _colour(i), _is_peer(name))
        label = name + (" (baseline)" if name == BASELINE else "")
        cv2.putText(img, label, (x + 34, y + 5), _FONT, 0.45, _BLACK, 1, cv2.LINE_AA)
    if any(_is_peer(n) for n in names):  # their errors are not against our references
        y = 40 + 22 * len(names) + 10
        for k, text in enumerate(("mujoco-*: error against", "MuJoCo's own reference")):
            cv2.putText(img, text, (x, y + 18 * k), _FONT, 0.42, _BLACK, 1, cv2.LINE_AA)
    return cv2.imencode(".png", img)[1].tobytes()
