"""Bend-and-release curves as pictures (OpenCV only): the joint's angle against time, measured
(solid) and as the isolated joint would do it (dashed), per axis; a vertical line at the
release.  One picture per joint (``joint_png``) and an overview of every joint
(``overview_png``)."""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np

from puppetcli.feel.measure import JointFeel, isolated_curve
from puppetcli.render.picture import write_png

__all__ = ["fit_png", "joint_png", "overview_png", "task_png", "write_plots"]

PANEL = (300, 480)  # (height, width) px of one joint's plot
MARGIN = (40, 56, 24, 36)  # top, left, right, bottom
COLOURS = {"swing": (180, 119, 31), "twist": (14, 127, 255)}  # BGR
_GREY, _BLACK, _WHITE = (225, 225, 225), (40, 40, 40), (255, 255, 255)
_FONT = cv2.FONT_HERSHEY_SIMPLEX


def _ticks(lo: float, hi: float, count: int = 5) -> np.ndarray:
    """Round tick values (1, 2 or 5 × 10^k apart) covering [lo, hi]."""
    raw = (hi - lo) / count if hi > lo else 1.0
    step = 10.0 ** math.floor(math.log10(raw))
    step *= next(m for m in (1, 2, 5, 10) if m * step >= raw)
    return np.arange(math.floor(lo / step), math.ceil(hi / step) + 1) * step


def _lines(
    title: str, note: str, series: list[tuple[np.ndarray, np.ndarray, tuple, bool]],
    size: tuple[int, int], marks: tuple[float, ...] = (),
) -> np.ndarray:  # fmt: skip
    """A plot of ``series`` (t, y, BGR colour, dashed) with round ticks, vertical lines at
    ``marks`` (times), a title and a note line."""
    h, w = size
    top, left, right, bottom = MARGIN
    img = np.full((h, w, 3), _WHITE, np.uint8)
    t_max = max(float(t[-1]) for t, *_ in series if len(t))
    values = np.concatenate([y for _, y, *_ in series])
    values = values[np.isfinite(values)]
    y_lo, y_hi = float(values.min()), float(values.max())
    if y_hi - y_lo < 1e-12:
        y_lo, y_hi = y_lo - 1.0, y_hi + 1.0
    xs, ys = _ticks(0.0, t_max), _ticks(y_lo, y_hi)
    x0, x1, y0, y1 = 0.0, float(xs[-1]), float(ys[0]), float(ys[-1])

    def px(t: np.ndarray, y: np.ndarray) -> np.ndarray:
        u = left + (t - x0) / (x1 - x0) * (w - left - right)
        v = h - bottom - (y - y0) / (y1 - y0) * (h - top - bottom)
        return np.stack((u, v), axis=1).round().astype(np.int32)

    for x in xs:
        u = int(px(np.array([x]), np.array([y0]))[0, 0])
        cv2.line(img, (u, top), (u, h - bottom), _GREY, 1)
        cv2.putText(img, f"{x:g}", (u - 8, h - bottom + 16), _FONT, 0.4, _BLACK, 1, cv2.LINE_AA)
    for y in ys:
        v = int(px(np.array([x0]), np.array([y]))[0, 1])
        cv2.line(img, (left, v), (w - right, v), _GREY, 1)
        cv2.putText(img, f"{y:g}", (4, v + 4), _FONT, 0.4, _BLACK, 1, cv2.LINE_AA)
    cv2.rectangle(img, (left, top), (w - right, h - bottom), _BLACK, 1)
    for t, y, colour, dashed in series:
        points = px(t, y)
        if not dashed:
            cv2.polylines(img, [points], False, colour, 2, cv2.LINE_AA)
            continue
        for k in range(0, len(points) - 1, 4):
            cv2.polylines(img, [points[k : k + 3]], False, colour, 1, cv2.LINE_AA)
    for m in marks:
        u = int(px(np.array([m]), np.array([y0]))[0, 0])
        cv2.line(img, (u, top), (u, h - bottom), _BLACK, 1)
    cv2.putText(img, title, (left, top - 22), _FONT, 0.5, _BLACK, 1, cv2.LINE_AA)
    cv2.putText(img, note, (left, top - 6), _FONT, 0.4, _BLACK, 1, cv2.LINE_AA)
    return img


def _panel(joint: JointFeel, size: tuple[int, int]) -> np.ndarray:
    series = []
    for a in joint.axes:
        colour = COLOURS.get(a.axis, _BLACK)
        t_iso, y_iso = isolated_curve(a)
        series += [(a.times, a.angles, colour, False), (t_iso, y_iso, colour, True)]
    legend = "  ".join(f"{a.axis}: retention {a.retention:.2f}" for a in joint.axes)
    return _lines(f"{joint.joint}: angle (deg) against time (s)",
                  legend + "   dashed: isolated joint", series, size,
                  (joint.axes[0].release,))  # fmt: skip


def fit_png(joint: str, fit) -> np.ndarray:
    """The fitted joint: its angle (on its busiest axis, degrees) as recorded (solid) and
    as the fitted model gives it (dashed), and the residual (grey), against time."""
    axis = int(np.argmax(np.var(fit.measured, axis=0)))
    measured, model = np.degrees(fit.measured[:, axis]), np.degrees(fit.model[:, axis])
    t = fit.times - fit.times[0]
    series = [(t, measured, COLOURS["swing"], False), (t, model, COLOURS["twist"], True),
              (t, measured - model, (150, 150, 150), False)]  # fmt: skip
    note = (f"kf {fit.kf:.4g}  df {fit.df:.4g}  dd {fit.dd:.4g}  residual "
            f"{np.degrees(fit.rms):.3g} deg rms   dashed: model, grey: residual")  # fmt: skip
    return _lines(f"{joint}: recorded and fitted angle (deg, axis {'xyz'[axis]})", note,
                  series, PANEL)  # fmt: skip


PALETTE = ((180, 119, 31), (14, 127, 255), (44, 160, 44), (40, 39, 214))  # BGR, per run
PALETTE_NAMES = ("blue", "orange", "green", "red")


def task_png(task: str, runs: Sequence) -> np.ndarray:
    """A task posed by each run (``TaskRun``): the worst joint's error (deg) against time
    (s) through its keys, one colour per run, the 2° line dashed."""
    series, legend, t_end = [], [], 0.0
    for k, run in enumerate(runs):
        t0, times, worst = 0.0, [], []
        for key in run.keys:
            trace = np.array(key.trace, dtype=float).reshape(-1, 2)
            times.append(t0 + trace[:, 0])
            worst.append(np.degrees(trace[:, 1]))
            t0 += key.duration
        series.append((np.concatenate(times), np.concatenate(worst), PALETTE[k % 4], False))
        legend.append(run.run)
        t_end = max(t_end, t0)
    series.append((np.array([0.0, t_end]), np.array([2.0, 2.0]), _BLACK, True))
    return _lines(f"{task}: worst joint error (deg) against time (s)",
                  "  ".join(f"{PALETTE_NAMES[k % 4]}: {n}"
                            for k, n in enumerate(legend)), series, PANEL)  # fmt: skip


def joint_png(joint: JointFeel) -> np.ndarray:
    """One joint's bend-and-release plot (BGR)."""
    return _panel(joint, PANEL)


def overview_png(joints: Sequence[JointFeel], cols: int = 4) -> np.ndarray:
    """Every joint's plot, small, in a grid (BGR)."""
    size = (PANEL[0] * 3 // 4, PANEL[1] * 3 // 4)
    panels = [_panel(j, size) for j in joints]
    rows = -(-len(panels) // cols)
    sheet = np.full((rows * size[0], min(cols, len(panels)) * size[1], 3), _WHITE, np.uint8)
    for k, p in enumerate(panels):
        r, c = divmod(k, cols)
        sheet[r * size[0] : (r + 1) * size[0], c * size[1] : (c + 1) * size[1]] = p
    return sheet


def write_plots(folder: Path, pictures: dict[str, np.ndarray]) -> list[str]:
    """Each picture as ``folder/NAME.png`` (a joint's name made a safe file name); the paths
    written."""
    folder.mkdir(parents=True, exist_ok=True)
    out = []
    for name, img in pictures.items():
        path = folder / (re.sub(r"[^\w.-]+", "_", name) + ".png")
        write_png(path, img)
        out.append(str(path))
    return out
