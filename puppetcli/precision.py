"""Work-precision study: error against run time of each solver setting and step.

Scenes (error measures):
- ``creep``: the paper's experiment (rigs/one_bone.yaml: τ = 1 N·m about z for 2 s,
  then free until 6 s); error = max over all steps of |θ − θ_exact| (rad), θ_exact the
  continuous model's solution by the matrix exponential (``creep_exact``, no solver).
- ``chain``: rigs/chain.yaml without ground (10 links, equality rows only) released
  under gravity; error = |tip − tip_ref| (m) after ``CHAIN_T`` s, tip_ref from the
  direct solver at ``reference_h`` (first order: its own error is about
  reference_h / h times the error at h; the study reports it as ``ref_error``).
The doll is not in the study (its contacts leave no converged reference).

Every run uses the compiled step (solver.fast.fast_step).  Time is the wall time of
the steps (time.perf_counter), best of ``repeats`` runs, after an untimed warm-up run
that compiles the kernels for the configuration.  Times are only comparable within
one run of the study (see DESIGN.md: speed is measured as ratios).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np
import scipy.linalg

from puppetcli.outputs import atomic_path, write_text_atomic
from puppetcli.rigfile import load_rig
from solver.fast import fast_step
from solver.model import Model, build_model
from solver.observe import bone_tails, joint_rotations
from solver.state import State, StepInput, initial_state

RIGS = Path(__file__).resolve().parent.parent / "rigs"

# The creep experiment (rigs/one_bone.yaml; digest §5.1, rotational form).
KF, DF, DD, INERTIA, TAU = 1.0, 10.0, 100.0, 0.1, 1.0
T_LOAD, T_END = 2.0, 6.0
CHAIN_T = 1.0


@dataclass(frozen=True)
class Setting:
    """One solver setting: Options fields method, iterations, warm_start(_factor)."""

    name: str
    method: str
    iterations: int = 15
    warm_start: bool = True
    warm_start_factor: float = 1.0


def _pgs(n: int, ws: bool, factor: float = 1.0) -> Setting:
    tag = f"pgs{n}" + ("" if not ws else "-ws" if factor == 1.0 else f"-ws{factor:g}")
    return Setting(tag, "pgs", n, ws, factor)


SETTINGS = [
    *(_pgs(n, ws, f) for n in (5, 15, 50) for ws, f in ((False, 1.0), (True, 1.0), (True, 0.7))),
    Setting("direct", "direct"),
    Setting("auto", "auto"),
]
QUICK_SETTINGS = [s for s in SETTINGS if s.name in ("pgs5", "pgs15-ws", "direct", "auto")]
STEPS_H = [0.001, 0.005, 0.02]
QUICK_STEPS_H = [0.005, 0.02]


@dataclass(frozen=True)
class PrecisionRow:
    """One (scene, setting, h): its error, wall seconds and steps."""

    scene: str
    setting: str
    h: float
    steps: int
    seconds: float
    error: float
    unit: str
    ref_error: float = 0.0


def creep_exact(times: np.ndarray) -> np.ndarray:
    """Angle θ(t) (rad) of the continuous creep model, exact by the matrix exponential.

    State (θ, ω, q_sf):  I ω̇ = τ + λ,  λ = −D_d (ω − q̇_sf) = −K_f q_sf − D_f q̇_sf
    ⇒ q̇_sf = (D_d ω − K_f q_sf)/(D_d + D_f); τ = TAU for t < T_LOAD, then 0.
    The constant input enters as a fourth, constant state of the augmented matrix.
    """
    s = DD + DF
    aug = np.zeros((4, 4))
    aug[:3, :3] = [
        [0.0, 1.0, 0.0],
        [0.0, -DD / INERTIA * (1 - DD / s), -DD * KF / (s * INERTIA)],
        [0.0, DD / s, -KF / s],
    ]

    def advance(x: np.ndarray, tau: float, dt: float) -> np.ndarray:
        a = aug.copy()
        a[1, 3] = tau / INERTIA
        return (scipy.linalg.expm(a * dt) @ np.append(x, 1.0))[:3]

    x_load = advance(np.zeros(3), TAU, T_LOAD)
    times = np.asarray(times, dtype=float)
    return np.array(
        [
            advance(np.zeros(3), TAU, t)[0] if t <= T_LOAD else advance(x_load, 0.0, t - T_LOAD)[0]
            for t in times
        ]
    )


def creep_model() -> Model:
    return build_model(load_rig(RIGS / "one_bone.yaml"))


def chain_model() -> Model:
    """rigs/chain.yaml without ground or self-collision: equality rows only."""
    spec = load_rig(RIGS / "chain.yaml")
    bones = tuple(replace(b, collide=False) for b in spec.bones)
    return build_model(replace(spec, ground=None, bones=bones))


def _run(model: Model, duration: float, loaded: StepInput | None) -> tuple[list[State], float]:
    """States after every step over ``duration`` and the wall seconds of the steps."""
    h = model.options.h
    n, n_load = round(duration / h), round(T_LOAD / h)
    state = initial_state(model)
    states = []
    start = time.perf_counter()
    for k in range(n):
        state, _ = fast_step(model, state, loaded if k < n_load else None)
        states.append(state)
    return states, time.perf_counter() - start


def _timed(model: Model, duration: float, loaded, repeats: int) -> tuple[list[State], float]:
    _run(model, min(duration, 10 * model.options.h), loaded)  # warm-up: compiles
    best = math.inf
    for _ in range(repeats):
        states, wall = _run(model, duration, loaded)
        best = min(best, wall)
    return states, best


def _configure(model: Model, setting: Setting, h: float) -> Model:
    return model.with_options(
        h=h,
        method=setting.method,
        iterations=setting.iterations,
        warm_start=setting.warm_start,
        warm_start_factor=setting.warm_start_factor,
    )


def creep_rows(settings: list[Setting], steps_h: list[float], repeats: int) -> list[PrecisionRow]:
    base = creep_model()
    loaded = StepInput(body_torque=np.array([[0.0, 0.0, TAU]]))
    rows = []
    for h in steps_h:
        exact = creep_exact(h * np.arange(1, round(T_END / h) + 1))
        for s in settings:
            model = _configure(base, s, h)
            states, wall = _timed(model, T_END, loaded, repeats)
            angles = np.array([joint_rotations(model, st)[0, 2] for st in states])
            err = float(np.max(np.abs(angles - exact)))
            rows.append(PrecisionRow("creep", s.name, h, len(states), wall, err, "rad"))
    return rows


def chain_reference(reference_h: float) -> tuple[np.ndarray, float]:
    """Tip position after CHAIN_T s by the direct solver at reference_h, and the distance
    to the tip at 2·reference_h (≈ the reference's own first-order error)."""
    tips = []
    for h in (reference_h, 2 * reference_h):
        model = _configure(chain_model(), Setting("direct", "direct"), h)
        states, _ = _run(model, CHAIN_T, None)
        tips.append(bone_tails(model, states[-1])[-1])
    return tips[0], float(np.linalg.norm(tips[1] - tips[0]))


def chain_rows(
    settings: list[Setting], steps_h: list[float], repeats: int, reference_h: float
) -> list[PrecisionRow]:
    tip_ref, ref_err = chain_reference(reference_h)
    base = chain_model()
    rows = []
    for h in steps_h:
        for s in settings:
            model = _configure(base, s, h)
            states, wall = _timed(model, CHAIN_T, None, repeats)
            err = float(np.linalg.norm(bone_tails(model, states[-1])[-1] - tip_ref))
            rows.append(PrecisionRow("chain", s.name, h, len(states), wall, err, "m", ref_err))
    return rows


def study(
    *,
    quick: bool = False,
    scenes: tuple[str, ...] = ("creep", "chain"),
    repeats: int | None = None,
    reference_h: float | None = None,
) -> list[PrecisionRow]:
    """Every (scene, setting, h) of the study; ``quick``: fewer settings and steps."""
    settings = QUICK_SETTINGS if quick else SETTINGS
    steps_h = QUICK_STEPS_H if quick else STEPS_H
    repeats = repeats or (1 if quick else 3)
    reference_h = reference_h or (0.0005 if quick else 0.0001)
    rows = []
    if "creep" in scenes:
        rows += creep_rows(settings, steps_h, repeats)
    if "chain" in scenes:
        rows += chain_rows(settings, steps_h, repeats, reference_h)
    return rows


def format_table(rows: list[PrecisionRow]) -> str:
    head = (
        f"{'scene':<6} {'setting':<14} {'h (s)':>6} {'steps':>6} {'seconds':>9} "
        f"{'error':>10} unit  {'× direct time':>13}"
    )
    lines = [head, "-" * len(head)]
    for r in rows:
        ratio = r.seconds / _direct_seconds(rows, r)
        lines.append(
            f"{r.scene:<6} {r.setting:<14} {r.h:>6g} {r.steps:>6} {r.seconds:>9.4f} "
            f"{r.error:>10.3e} {r.unit:<4}  {ratio:>13.2f}"
        )
    refs = {r.scene: r.ref_error for r in rows if r.ref_error}
    lines += [f"{k}: reference's own error ≈ {v:.1e}" for k, v in refs.items()]
    return "\n".join(lines)


def _direct_seconds(rows: list[PrecisionRow], row: PrecisionRow) -> float:
    same = [r.seconds for r in rows if (r.scene, r.h, r.setting) == (row.scene, row.h, "direct")]
    return same[0] if same and same[0] > 0 else row.seconds or 1.0


def csv_text(rows: list[PrecisionRow]) -> str:
    fields = list(PrecisionRow.__dataclass_fields__)
    out = [",".join(fields)]
    out += [",".join(str(getattr(r, f)) for f in fields) for r in rows]
    return "\n".join(out) + "\n"


PANEL_W, PANEL_H, LEGEND_W, MARGIN = 560, 440, 170, 60
PLOT_SIZE = (PANEL_H, 2 * PANEL_W + LEGEND_W)  # (height, width) pixels of the PNG
_WHITE, _GREY, _BLACK = (255, 255, 255), (220, 220, 220), (0, 0, 0)


_PALETTE = [  # BGR, distinct (tab10-like, then black and grey)
    (180, 119, 31), (14, 127, 255), (44, 160, 44), (40, 39, 214), (189, 103, 148),
    (75, 86, 140), (194, 119, 227), (34, 189, 188), (207, 190, 23), (0, 0, 0), (127, 127, 127),
]  # fmt: skip


def _colour(i: int) -> tuple[int, int, int]:
    return _PALETTE[i % len(_PALETTE)]


def _panel(img: np.ndarray, x0: int, rows: list[PrecisionRow], names: list[str]) -> None:
    """One scene's log-log panel: error (y) against seconds (x), one polyline per setting."""
    ok = [r for r in rows if np.isfinite(r.error) and r.seconds > 0]
    if not ok:
        return
    lx = np.log10([r.seconds for r in ok])
    ly = np.log10([max(r.error, 1e-16) for r in ok])
    xr = (math.floor(lx.min()), math.ceil(lx.max()) + (lx.max() == math.ceil(lx.max())))
    yr = (math.floor(ly.min()), math.ceil(ly.max()) + (ly.max() == math.ceil(ly.max())))
    left, top, right, bottom = x0 + MARGIN, 30, x0 + PANEL_W - 15, PANEL_H - 45

    def px(t: float, e: float) -> tuple[int, int]:
        u = (math.log10(t) - xr[0]) / (xr[1] - xr[0])
        v = (math.log10(max(e, 1e-16)) - yr[0]) / (yr[1] - yr[0])
        return round(left + u * (right - left)), round(bottom - v * (bottom - top))

    font = cv2.FONT_HERSHEY_SIMPLEX
    for d in range(xr[0], xr[1] + 1):
        x = px(10.0**d, 10.0 ** yr[0])[0]
        cv2.line(img, (x, top), (x, bottom), _GREY, 1)
        cv2.putText(img, f"1e{d}", (x - 14, bottom + 18), font, 0.4, _BLACK, 1, cv2.LINE_AA)
    for d in range(yr[0], yr[1] + 1):
        y = px(10.0 ** xr[0], 10.0**d)[1]
        cv2.line(img, (left, y), (right, y), _GREY, 1)
        cv2.putText(img, f"1e{d}", (x0 + 8, y + 4), font, 0.4, _BLACK, 1, cv2.LINE_AA)
    cv2.rectangle(img, (left, top), (right, bottom), _BLACK, 1)
    title = f"{ok[0].scene}: error ({ok[0].unit}) vs run time (s)"
    cv2.putText(img, title, (left, 20), font, 0.5, _BLACK, 1, cv2.LINE_AA)
    cv2.putText(img, "run time (s)", (left + 180, PANEL_H - 10), font, 0.45, _BLACK, 1)
    for i, name in enumerate(names):
        pts = sorted((r.seconds, r.error) for r in ok if r.setting == name)
        xy = np.array([px(t, e) for t, e in pts], dtype=np.int32).reshape(-1, 1, 2)
        cv2.polylines(img, [xy], False, _colour(i), 2, cv2.LINE_AA)
        for p in xy[:, 0]:
            cv2.circle(img, (int(p[0]), int(p[1])), 3, _colour(i), -1, cv2.LINE_AA)


def plot_png(rows: list[PrecisionRow]) -> bytes:
    """The study as a PNG: one log-log panel per scene (up to two), a shared legend."""
    img = np.full((*PLOT_SIZE, 3), 255, dtype=np.uint8)
    names = list(dict.fromkeys(r.setting for r in rows))
    for k, scene in enumerate(list(dict.fromkeys(r.scene for r in rows))[:2]):
        _panel(img, k * PANEL_W, [r for r in rows if r.scene == scene], names)
    for i, name in enumerate(names):
        y = 40 + 22 * i
        cv2.line(img, (2 * PANEL_W + 5, y), (2 * PANEL_W + 30, y), _colour(i), 3)
        cv2.putText(img, name, (2 * PANEL_W + 36, y + 5), cv2.FONT_HERSHEY_SIMPLEX, 0.45, _BLACK, 1)
    return cv2.imencode(".png", img)[1].tobytes()


def write_outputs(rows: list[PrecisionRow], out_dir: Path) -> tuple[Path, Path]:
    """precision.csv and precision.png in out_dir (replaced if present)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    csv_path, png_path = out_dir / "precision.csv", out_dir / "precision.png"
    write_text_atomic(csv_path, csv_text(rows))
    with atomic_path(png_path) as tmp:
        tmp.write_bytes(plot_png(rows))
    return csv_path, png_path
