"""Write keyframes of a rig as a BVH motion (see ``puppetcli.bvh.model`` and docs/bvh.md).

Hierarchy: one JOINT per bone, depth first in rig order; OFFSET = child head −
parent head at rest (× scale); the root has OFFSET 0 0 0 and 6 channels
(``Xposition Yposition Zposition`` + 3 rotations), its head travelling in the
position channels; other joints have 3 rotation channels, all in one order
(ZXY unless asked); every leaf has an End Site at its tail.

Frames: per bone the keyframes' ``local`` rotation as Euler angles in degrees
(double precision), unwrapped from frame to frame (``puppetcli.bvh.model.unwrap_euler``).
Either one frame per key, or the motion resampled at ``fps`` from the first
key's time to the last: local rotations slerped, root position linear.

Formatting is deterministic: tabs, single spaces between numbers, fixed point
(6 decimals for degrees: < 1e-8 rad; 9 for lengths in file units), no ``-0``,
LF line ends, a final newline, ``Frame Time`` with 10 significant digits.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from puppetcli.bvh.model import ORDERS, euler_from_quat, unwrap_euler
from puppetcli.errors import shown
from puppetcli.naming import deduplicated
from puppetcli.outputs import write_text_atomic
from puppetcli.rig.skeleton import Skeleton
from puppetcli.run.keyframes import BonePose, Keyframe
from puppetcli.run.snapshot import capture
from solver import quat
from solver.model import Model
from solver.state import State

__all__ = [
    "FrameSampler",
    "bvh_names",
    "bvh_text",
    "interpolate_keys",
    "resample_keys",
    "write_keys_bvh",
]

ANGLE_DECIMALS = 6
LENGTH_DECIMALS = 9
FRAME_TIME_DIGITS = 10


def write_keys_bvh(
    path: Path,
    skel: Skeleton,
    keys: list[Keyframe],
    order: str = "ZXY",
    scale: float = 1.0,
    fps: float = 30.0,
    interpolate: str | None = None,
) -> None:
    """Write ``keys`` as a BVH file atomically.

    order: rotation channel order, one of ``ORDERS``; scale: file units per
    metre (100 for centimetres); fps: frames per second (Frame Time = 1/fps);
    interpolate: None = one frame per key, ``"slerp"`` = the motion sampled at
    ``fps`` between the keys' times.
    """
    if interpolate not in (None, "slerp"):
        raise ValueError(f"interpolate must be None or 'slerp', got {shown(interpolate)}")
    keys = list(keys)  # a KeyframeSet or any iterable of keys in time order
    if interpolate == "slerp":
        keys = resample_keys(keys, fps)
    write_text_atomic(Path(path), bvh_text(skel, keys, order, scale, 1.0 / fps))


def bvh_text(
    skel: Skeleton, keys: Sequence[Keyframe], order: str, scale: float, frame_time: float
) -> str:
    """The whole BVH file: hierarchy, then one frame line per key."""
    order = order.upper()
    if order not in ORDERS:
        raise ValueError(f"order must be one of {', '.join(ORDERS)}, got {shown(order)}")
    if not (math.isfinite(scale) and scale > 0.0):
        raise ValueError(f"scale must be positive and finite, got {shown(scale)}")
    if not (math.isfinite(frame_time) and frame_time > 0.0):
        raise ValueError(f"frame time must be positive and finite, got {shown(frame_time)}")
    bones = _depth_first(skel.parents)
    lines = ["HIERARCHY"]
    _joint_lines(skel, bones[0], order, scale, bvh_names(skel.names), lines)
    lines += ["MOTION", f"Frames: {len(keys)}", f"Frame Time: {_frame_time(frame_time)}"]
    lines += [" ".join(row) for row in _frame_rows(skel, bones, keys, order, scale)]
    return "\n".join(lines) + "\n"


def bvh_names(names: Sequence[str]) -> tuple[str, ...]:
    """Joint names BVH readers agree on: whitespace and braces become ``_``, then
    duplicates (and empty names) get a ``_2``, ``_3`` … suffix.  Other names are kept."""
    return deduplicated((re.sub(r"[\s{}]+", "_", n) or "joint" for n in names),
                        lambda k: f"_{k + 1}")  # fmt: skip


def _depth_first(parents: np.ndarray) -> list[int]:
    """Bone indices depth first from the root, children in rig order."""
    children: dict[int, list[int]] = {}
    for i, p in enumerate(parents):
        children.setdefault(int(p), []).append(i)
    roots = children.get(-1, [])
    if len(roots) != 1:
        raise ValueError(f"a BVH hierarchy needs exactly one root bone, got {len(roots)}")
    order: list[int] = []
    stack = [roots[0]]
    while stack:
        i = stack.pop()
        order.append(i)
        stack.extend(reversed(children.get(i, [])))
    return order


def _joint_lines(
    skel: Skeleton, root: int, order: str, scale: float, names: tuple[str, ...], lines: list[str]
) -> None:
    """The ROOT block of bone ``root`` and its subtree, nested JOINT blocks depth first (an
    explicit stack: a chain of any length costs no recursion)."""
    children: dict[int, list[int]] = {}
    for c, p in enumerate(skel.parents):
        children.setdefault(int(p), []).append(c)
    rotations = " ".join(f"{axis}rotation" for axis in order)
    stack = [(root, 0, False)]
    while stack:
        i, depth, closing = stack.pop()
        pad = "\t" * depth
        if closing:
            if not children.get(i):
                tip = (skel.tail0[i] - skel.head0[i]) * scale
                lines += [f"{pad}\tEnd Site", f"{pad}\t{{", f"{pad}\t\tOFFSET {_lengths(tip)}"]
                lines.append(f"{pad}\t}}")
            lines.append(f"{pad}}}")
            continue
        p = int(skel.parents[i])
        offset = np.zeros(3) if p < 0 else (skel.head0[i] - skel.head0[p]) * scale
        channels = f"6 Xposition Yposition Zposition {rotations}" if p < 0 else f"3 {rotations}"
        lines += [f"{pad}{'ROOT' if p < 0 else 'JOINT'} {names[i]}", f"{pad}{{"]
        lines += [f"{pad}\tOFFSET {_lengths(offset)}", f"{pad}\tCHANNELS {channels}"]
        stack.append((i, depth, True))
        stack.extend((c, depth + 1, False) for c in reversed(children.get(i, [])))


def _frame_rows(
    skel: Skeleton, bones: list[int], keys: Sequence[Keyframe], order: str, scale: float
) -> list[list[str]]:
    """Per key: root position (× scale), then every joint's unwrapped Euler angles."""
    if not keys:
        return []
    names = [skel.names[i] for i in bones]
    for key in keys:
        missing = [n for n in names if n not in key.bones]
        if missing:
            raise ValueError(f"key at t = {key.time!r} s has no bone {missing[0]!r}")
    local = np.array([[key.bones[n].local for n in names] for key in keys], dtype=float)
    angles = euler_from_quat(local.reshape(-1, 4), order).reshape(len(keys), len(names), 3)
    angles = unwrap_euler(angles)
    root = np.array([key.bones[names[0]].head for key in keys], dtype=float) * scale
    return [
        [_fixed(x, LENGTH_DECIMALS) for x in root[f]]
        + [_fixed(x, ANGLE_DECIMALS) for x in angles[f].ravel()]
        for f in range(len(keys))
    ]


def _fixed(x: float, decimals: int) -> str:
    """Fixed point without exponent and without a negative zero."""
    text = f"{x:.{decimals}f}"
    return text[1:] if text.startswith("-") and not text.strip("-0.") else text


def _lengths(v: np.ndarray) -> str:
    return " ".join(_fixed(x, LENGTH_DECIMALS) for x in v)


def _frame_time(seconds: float) -> str:
    """``seconds`` to 10 significant digits, fixed point, trailing zeros dropped."""
    decimals = max(1, FRAME_TIME_DIGITS - 1 - math.floor(math.log10(seconds)))
    text = f"{seconds:.{decimals}f}".rstrip("0")
    return text + "0" if text.endswith(".") else text


# ---- timed motion: keys resampled at a frame rate ----


def resample_keys(keys: Sequence[Keyframe], fps: float) -> list[Keyframe]:
    """Keys at t0 + k/fps for every k with t0 + k/fps ≤ t_last (t0 = the first key's time),
    interpolated between the keys around each time (see ``interpolate_keys``)."""
    if not (math.isfinite(fps) and fps > 0.0):
        raise ValueError(f"fps must be positive and finite, got {shown(fps)}")
    keys = sorted(keys, key=lambda k: k.time)
    if not keys:
        return []
    t0, span = keys[0].time, keys[-1].time - keys[0].time
    count = math.floor(span * fps + 1e-9) + 1
    out: list[Keyframe] = []
    j = 0
    for k in range(count):
        t = t0 + k / fps
        while j + 2 < len(keys) and keys[j + 1].time <= t:
            j += 1
        a, b = keys[j], keys[min(j + 1, len(keys) - 1)]
        out.append(interpolate_keys(a, b, t, f"frame {k}"))
    return out


def interpolate_keys(a: Keyframe, b: Keyframe, t: float, label: str = "") -> Keyframe:
    """The pose at time ``t`` between keys ``a`` and ``b``: heads linear, ``rotation`` and
    ``local`` slerped along the shorter arc, u = (t − t_a)/(t_b − t_a) clipped to [0, 1]."""
    span = b.time - a.time
    u = 0.0 if span <= 0.0 else min(max((t - a.time) / span, 0.0), 1.0)
    bones = {
        name: BonePose(
            head=(1.0 - u) * pose.head + u * b.bones[name].head,
            rotation=_slerp(pose.rotation, b.bones[name].rotation, u),
            local=_slerp(pose.local, b.bones[name].local, u),
        )
        for name, pose in a.bones.items()
    }
    return Keyframe(time=t, label=label, bones=bones)


def _slerp(q0: np.ndarray, q1: np.ndarray, u: float) -> np.ndarray:
    """q0 ⊗ exp(u · log(q0⁻¹ ⊗ q1)): constant angular speed, shorter arc (log picks it)."""
    q = quat.mul(q0, quat.exp(u * quat.log(quat.mul(quat.conj(q0), q1))))
    q = q / np.linalg.norm(q)
    return -q if q[0] < 0.0 else q


class FrameSampler:
    """An ``on_step`` callback that keeps the pose at every t_k = k/fps.

    A step rarely lands on t_k, so the pose there is interpolated between the
    states before and after it (heads linear, rotations slerped): the frames are
    the motion at exact frame times, whatever the step h.
    """

    def __init__(self, model: Model, fps: float, state: State) -> None:
        self.model, self.fps = model, fps
        self.frames: list[Keyframe] = [capture(model, state, "frame 0", {})]
        self.previous = state

    def __call__(self, state: State) -> None:
        t_next = len(self.frames) / self.fps
        if state.time >= t_next - 1e-9:
            before = capture(self.model, self.previous, "", {})
            after = capture(self.model, state, "", {})
            while state.time >= t_next - 1e-9:
                k = len(self.frames)
                self.frames.append(interpolate_keys(before, after, t_next, f"frame {k}"))
                t_next = (k + 1) / self.fps
        self.previous = state
