"""How a rig feels, measured by simulating it as it is (docs/feel.md).

Per joint, on two axes (``axes``): *swing*, a world axis across the bone (z, else
x), and *twist*, the bone's own axis, both at rest.  Each measure is one run of the
rig from rest, gravity, neighbours, limits and contacts included:

- **bend** (``bend_run``): a stiff 6-DOF grip on the joint's bone at the joint
  turns it by ``angle`` about the axis through the joint in ``duration`` (a
  ``rotate`` with a minimum-jerk profile), lets go and watches ``WATCH`` s.
  *effort*: the grip's peak torque (N·m) and the force at the bone's tip that
  gives it (torque / bone length); *joint torque*: the peak of the joint's
  rheology torque on the axis; *retention*: the angle kept ``RETAIN`` s after
  release over the angle at release; *spring-back*: a + b·e^(−t/T) fitted to the
  angle after release, b the angle given back and T its time constant;
  *hold (bent)*: the drift over the ``HOLD`` s after the retention window;
  *flow onset*: the joint's filtered torque when it first yields.
- **creep** (``creep_run``): a constant torque on the bone about the axis, below
  the yield torque (``creep_torque``), for ``creep_time`` s; a + b·e^(−t/T) + c·t
  fitted to the angle, c the creep rate.
- **hold (rest)** (``rest_run``): the rig left alone ``HOLD`` s: each joint's
  drift, and whether gravity alone makes it yield.

The grip is made stiff for the joint (``GRIP_FACTOR`` × the joint's own
stiffness over the bend), so the bend is the one asked for, to a fraction of a
percent.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from puppetcli.feel.isolated import IsolatedJoint
from puppetcli.run.runner import Runner, script_model
from puppetcli.script.actions import Grip, Release, Rotate
from puppetcli.script.load import Push, Script, Wait
from solver.model import Model
from solver.observe import joint_rotations

__all__ = ["AxisFeel", "JointFeel", "axes", "isolated_curve", "measure_joint", "rest_run"]

RETAIN = 2.0  # s after release: retention
HOLD = 10.0  # s: hold drift windows
WATCH = RETAIN + HOLD  # s watched after release
GRIP_FACTOR = 1000.0  # grip stiffness / the joint's stiffness over the bend
CREEP_ANGLE = math.radians(5.0)  # the creep torque's elastic angle, K_f · 5°
CREEP_SHARE = 0.5  # of the yield torque at most


@dataclass
class AxisFeel:
    """One axis of one joint, measured and predicted (``isolated``: the same measures of
    the joint alone, puppetcli.feel.isolated).  Angles in degrees, torques N·m, forces N,
    times s; NaN where a measure does not apply."""

    joint: str
    axis: str
    vector: np.ndarray
    bend: float
    effort: float
    tip_force: float
    joint_torque: float
    retention: float
    springback: float
    springback_time: float
    hold_bent: float
    flow_onset: float
    creep: float
    creep_torque: float
    times: np.ndarray = field(repr=False)
    angles: np.ndarray = field(repr=False)
    release: float = 0.0
    isolated: dict[str, float] = field(default_factory=dict)
    joint_model: IsolatedJoint | None = None
    target: float = 0.0  # rad: the bend asked for
    duration: float = 1.0  # s: its time


@dataclass
class JointFeel:
    """A joint: yield torque (N·m, inf: none); hold (rest): drift over HOLD s from rest
    (degrees); gravity_yields: gravity alone made it flow; its axes."""

    joint: str
    yield_torque: float
    hold_rest: float
    gravity_yields: bool
    axes: list[AxisFeel]


def axes(model: Model, j: int) -> dict[str, np.ndarray]:
    """{"swing": a world axis across the bone, "twist": the bone's axis}, unit vectors."""
    b = model.joint_bone[j]
    along = model.bone_tail0[b] - model.bone_head0[b]
    length = float(np.linalg.norm(along))
    d = along / length if length > 1e-9 else np.array([0.0, 1.0, 0.0])
    for e in (np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0])):
        if abs(float(e @ d)) < 0.9:
            s = e - (e @ d) * d
            return {"swing": s / np.linalg.norm(s), "twist": d}
    raise AssertionError("unreachable: z and x cannot both be within 26° of one direction")


def isolated_joint(model: Model, j: int, a: np.ndarray) -> IsolatedJoint:
    """The joint's coefficients on axis ``a`` (its parent's frame, world-aligned at rest)."""
    w = a * a
    dd = model.joint_dd[j]
    dd_a = float(w @ dd) if np.all(np.isfinite(dd)) else math.inf  # inf: never flows
    return IsolatedJoint(float(w @ model.joint_kf[j]), float(w @ model.joint_df[j]), dd_a,
                         float(model.joint_yield[j]))  # fmt: skip


class _Recorder:
    """on_step: time, the joint's angle about an axis (rad), its torque on the axis, the
    grip's torque on the bone, the filtered torque and yield flag."""

    def __init__(self, model: Model, j: int, a: np.ndarray) -> None:
        self.model, self.j, self.a = model, j, a
        self.rows: list[tuple[float, float, float, float, float, bool]] = []
        self.runner: Runner | None = None

    def __call__(self, state) -> None:
        rot = joint_rotations(self.model, state)[self.j]
        grip = self.runner.sim.wrench()[1] if self.runner is not None else np.zeros(3)
        torque = float(state.joint_torque[self.j] @ self.a)
        self.rows.append((state.time, float(rot @ self.a), torque, float(np.linalg.norm(grip)),
                          float(state.joint_torque_avg[self.j]),
                          bool(state.joint_yielded[self.j])))  # fmt: skip

    def array(self) -> np.ndarray:
        return np.array(self.rows, dtype=float).reshape(-1, 6)


def _run(model: Model, actions: tuple, on_step, pointer: np.ndarray | None = None):
    """Run ``actions`` on the rig from rest, ``on_step`` called after every step (a
    ``_Recorder`` is given the runner, to read the grip's wrench): the RunResult."""
    extra = {} if pointer is None else {"pointer_start": pointer}
    script = Script(source="<feel>", h=None, duration=None, gravity=True, actions=actions,
                    **extra)  # fmt: skip
    runner = Runner(script_model(model, script), script, on_step=on_step)
    if isinstance(on_step, _Recorder):
        on_step.runner = runner
    result = runner.run()
    if result.error is not None:
        raise result.error
    return result


def bend_run(
    model: Model, j: int, a: np.ndarray, angle: float, duration: float, watch: float = WATCH
) -> np.ndarray:
    """Rows (t, angle, joint torque, grip torque, filtered torque, yielded) of the bend and
    ``watch`` s after it."""
    iso = isolated_joint(model, j, a)
    flow = iso.dd if math.isfinite(iso.dd) else 0.0
    k = GRIP_FACTOR * max(iso.kf + (iso.df + flow) / duration, 10.0)
    b = model.joint_bone[j]
    grip = Grip(bone=model.bone_names[b], point=np.zeros(3), reach=0.15, stiffness=1e4,
                damping=100.0, rot_stiffness=k, rot_damping=2.0 * k * model.options.h,
                force_limit=1e6, torque_limit=1e6, position_only=False, line=0)  # fmt: skip
    actions = (grip, Rotate(axis=a, angle=angle, duration=duration, line=0),  # radians
               Release(line=0), Wait(duration=watch, line=0))  # fmt: skip
    recorder = _Recorder(model, j, a)
    _run(model, actions, recorder, model.bone_head0[b].copy())
    return recorder.array()


def creep_torque(iso: IsolatedJoint) -> float:
    """K_f · 5°, and at most half the yield torque (N·m); NaN when neither is finite."""
    options = [iso.kf * CREEP_ANGLE] if iso.kf > 0.0 else []
    options += [CREEP_SHARE * iso.yield_] if math.isfinite(iso.yield_) else []
    return min(options) if options else math.nan


def creep_time(iso: IsolatedJoint) -> float:
    """Long enough for the elastic part to settle: 5 T_r, between 2 and 20 s."""
    return float(np.clip(5.0 * iso.springback_time, 2.0, 20.0))


def creep_run(model: Model, j: int, a: np.ndarray, torque: float, duration: float) -> np.ndarray:
    b = model.joint_bone[j]
    push = Push(bone=model.bone_names[b], force=np.zeros(3), torque=torque * a,
                point=np.zeros(3), duration=duration, line=0)  # fmt: skip
    recorder = _Recorder(model, j, a)
    _run(model, (push,), recorder)
    return recorder.array()


def rest_run(model: Model) -> tuple[np.ndarray, np.ndarray]:
    """(drift of every joint over HOLD s from rest (rad), whether it yielded)."""
    yielded = np.zeros(model.njoint, dtype=bool)
    first: list[np.ndarray] = []

    def watch(state) -> None:
        yielded[:] |= state.joint_yielded
        if not first:
            first.append(joint_rotations(model, state))

    result = _run(model, (Wait(duration=HOLD, line=0),), watch)
    drift = np.linalg.norm(joint_rotations(model, result.state) - first[0], axis=1)
    return drift, yielded


def _fit_decay(t: np.ndarray, y: np.ndarray, guess: float, line: bool) -> tuple:
    """Least squares of y = a + b·e^(−t/T) (+ c·t): (a, b, T, c); NaNs when it fails."""
    from scipy.optimize import curve_fit

    def f(t, a, b, log_t, c=0.0):
        return a + b * np.exp(-t / np.exp(log_t)) + c * t

    span = max(float(t[-1] - t[0]), 1e-9)
    start = [y[-1], y[0] - y[-1], math.log(min(max(guess, 1e-3), 1e3))] + ([0.0] if line else [])
    try:
        p, _ = curve_fit(f, t - t[0], y, p0=start, maxfev=20000)
    except (RuntimeError, ValueError):
        return math.nan, math.nan, math.nan, math.nan
    tau = math.exp(p[2])
    if not math.isfinite(tau) or tau > 1e3 * span:
        return math.nan, math.nan, math.nan, math.nan
    return p[0], p[1], tau, (p[3] if line else 0.0)


def measure_axis(
    model: Model, j: int, name: str, a: np.ndarray, angle: float, duration: float,
    quick: bool = False,
) -> AxisFeel:  # fmt: skip
    """One axis's measures; ``quick``: no creep run and a watch only long enough for the
    retention and the spring-back (``fit`` uses it)."""
    iso = isolated_joint(model, j, a)
    watch = max(RETAIN, 5.0 * iso.springback_time) + 0.5 if quick else WATCH
    rows = bend_run(model, j, a, angle, duration, min(watch, WATCH))
    t, theta = rows[:, 0], rows[:, 1]
    during = t <= duration + 1e-9
    k_rel = int(np.flatnonzero(during)[-1])
    theta_r = theta[k_rel]
    after = t >= t[k_rel]
    k_keep = int(np.searchsorted(t, t[k_rel] + RETAIN - 1e-9))
    k_keep = min(k_keep, len(t) - 1)
    _, b, tau, _ = _fit_decay(t[after], theta[after], iso.springback_time, line=False)
    b_len = float(np.linalg.norm(model.bone_tail0[model.joint_bone[j]]
                                 - model.bone_head0[model.joint_bone[j]]))  # fmt: skip
    effort = float(rows[during, 3].max())
    onset = np.flatnonzero(rows[:, 5] > 0.5)
    torque_c = creep_torque(iso)
    creep = math.nan
    if math.isfinite(torque_c) and not quick:
        crow = creep_run(model, j, a, torque_c, creep_time(iso))
        creep = _fit_decay(crow[:, 0], crow[:, 1], iso.springback_time, line=True)[3]
    feel = AxisFeel(
        joint=model.joint_names[j], axis=name, vector=a, bend=math.degrees(theta_r),
        effort=effort, tip_force=effort / b_len if b_len > 1e-9 else math.nan,
        joint_torque=float(np.abs(rows[during, 2]).max()),
        retention=float(theta[k_keep] / theta_r) if abs(theta_r) > 1e-12 else math.nan,
        springback=math.degrees(b), springback_time=tau,
        hold_bent=math.degrees(abs(theta[-1] - theta[k_keep])),
        flow_onset=float(rows[onset[0], 4]) if len(onset) else math.nan,
        creep=math.degrees(creep), creep_torque=torque_c,
        times=t, angles=np.degrees(theta), release=float(t[k_rel]),
    )  # fmt: skip
    feel.isolated = _predicted(iso, angle, duration, b_len, torque_c)
    feel.joint_model, feel.target, feel.duration = iso, angle, duration
    return feel


def isolated_curve(a: AxisFeel) -> tuple[np.ndarray, np.ndarray]:
    """(times, angles in degrees) of the isolated joint through ``a``'s bend and release."""
    iso = a.joint_model
    if iso is None:
        return np.zeros(0), np.zeros(0)
    bend = iso.bend(a.target, a.duration, steps=200)
    after = np.linspace(0.0, float(a.times[-1]) - a.duration, 400)
    decay = np.exp(-after / iso.springback_time) if iso.kf > 0.0 else np.ones_like(after)
    back = bend.angle[-1] - bend.elastic[-1] * (1.0 - decay)
    return (np.concatenate((bend.times, a.duration + after)),
            np.degrees(np.concatenate((bend.angle, back))))  # fmt: skip


def _predicted(iso: IsolatedJoint, angle: float, duration: float, length: float,
               torque_c: float) -> dict[str, float]:  # fmt: skip
    bend = iso.bend(angle, duration)
    return {
        "bend": math.degrees(angle),
        "effort": bend.peak_torque,
        "tip_force": bend.peak_torque / length if length > 1e-9 else math.nan,
        "joint_torque": bend.peak_torque,
        "retention": iso.retention(bend, RETAIN),
        "springback": math.degrees(float(bend.elastic[-1])),
        "springback_time": iso.springback_time,
        "creep": math.degrees(iso.creep_rate(torque_c)) if math.isfinite(torque_c) else math.nan,
        "flow_onset": iso.yield_ if bend.flows and math.isfinite(iso.yield_) else math.nan,
    }


def measure_joint(
    model: Model, j: int, angle: float, duration: float, hold: tuple[np.ndarray, np.ndarray]
) -> JointFeel:
    """Every axis of joint ``j``; ``hold``: ``rest_run``'s result for the rig."""
    found = [measure_axis(model, j, name, a, angle, duration) for name, a in axes(model, j).items()]
    return JointFeel(model.joint_names[j], float(model.joint_yield[j]),
                     math.degrees(float(hold[0][j])), bool(hold[1][j]), found)  # fmt: skip
