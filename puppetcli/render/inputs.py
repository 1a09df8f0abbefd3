"""What ``puppetcli render`` can draw: poses read from keyframes.json, a BVH file or a trace.

- ``keyframes.json``: one pose per key (``puppetcli.rig.skeleton.key_pose``).
- ``.bvh``: through ``read_bvh`` of ``puppetcli.bvh.model`` or ``puppetcli.bvh.read``
  when one exists (otherwise a clear "not supported yet" error).  Joints match
  bones by name; each frame's forward kinematics gives bone heads and world
  rotations (the BVH rest pose is the rig's rest pose, as ``puppetcli.bvh.model``
  writes it); file units are scaled to metres by the ratio of the rig's
  joint-to-joint lengths to the file's.  At most ``MAX_BVH_PANELS`` frames,
  evenly spaced, make a sheet.
- ``trace.mcap``: one pose per recorded step.  Head and tail of every bone come
  from the ``/puppet/bones`` line list (in the ``/tf`` bone order), the bone
  rotations from ``/tf`` (composed down the tree; without ``/tf``, the shortest
  arc from the rest axis, which loses a box's twist), the pointer and its
  coupling line from ``/puppet/pointer``.  Key moments are the
  ``/puppet/keyframe`` events, each shown with the recorded step nearest to it (an
  ``undo`` event drops the latest).

Every input needs the rig (``--rig``) for bone shapes, props and the ground.
"""

from __future__ import annotations

import bisect
import importlib
import re
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from puppetcli.errors import shown
from puppetcli.mcap.trace import PUPPET_FRAME, read_trace
from puppetcli.render.camera import RenderError
from puppetcli.render.picture import Pose, poses_from_keys
from puppetcli.rig.skeleton import Skeleton
from puppetcli.run.keyframes import read_keyframes
from puppetcli.yamldoc import LARGEST
from solver import quat

__all__ = ["INPUT_KINDS", "input_kind", "key_poses", "trace_poses"]

INPUT_KINDS = {".json": "keyframes", ".bvh": "bvh", ".mcap": "trace"}
SAMPLED_PANELS = 9  # panels of a sheet of a trace without key events
_BVH_API = ("names", "nframes", "frame_time", "forward_kinematics")  # what we use of a BVH
MAX_BVH_PANELS = 48  # frames of a BVH shown at most (evenly spaced, first and last included)


def input_kind(path: Path) -> str:
    """``keyframes``, ``bvh`` or ``trace``, from the file name's suffix."""
    kind = INPUT_KINDS.get(Path(path).suffix.lower())
    if kind is None:
        raise RenderError(
            f"{path}: expected keyframes.json, a .bvh file or a trace .mcap, "
            f"got a {Path(path).suffix or 'suffix-less'} file"
        )
    return kind


def _bvh_reader() -> Callable[[Path], Any] | None:
    """``read_bvh`` of ``puppetcli.bvh.model`` or ``puppetcli.bvh.read``, if either exists."""
    for name in ("puppetcli.bvh.model", "puppetcli.bvh.read"):
        try:
            module = importlib.import_module(name)
        except ImportError:
            continue
        if callable(getattr(module, "read_bvh", None)):
            return module.read_bvh
    return None


def _bvh_index(skel: Skeleton, names: Sequence[str], path: Path) -> np.ndarray:
    """Index of each rig bone among the BVH joints: same name, or the name with runs of
    whitespace and braces replaced by ``_`` (as BVH writers must)."""
    index = {n: i for i, n in enumerate(names)}
    out = []
    for bone in skel.names:
        i = index.get(bone, index.get(re.sub(r"[\s{}]+", "_", bone)))
        if i is None:
            raise RenderError(
                f"{path}: expected a joint for every bone of the rig, got no {bone!r}"
            )
        out.append(i)
    return np.array(out)


def _bvh_scale(skel: Skeleton, rest: np.ndarray, index: np.ndarray) -> float:
    """Metres per BVH file unit: the rig's joint-to-joint lengths over the file's, at rest."""
    child = np.flatnonzero(skel.parents >= 0)
    parent = skel.parents[child]
    rig = np.linalg.norm(skel.head0[child] - skel.head0[parent], axis=1).sum()
    bvh = np.linalg.norm(rest[index[child]] - rest[index[parent]], axis=1).sum()
    return float(rig / bvh) if bvh > 0.0 and rig > 0.0 else 1.0


def bvh_poses(path: Path, skel: Skeleton) -> list[Pose]:
    """Frames of a BVH file as poses of the rig (at most ``MAX_BVH_PANELS``, evenly spaced)."""
    reader = _bvh_reader()
    if reader is None:
        raise RenderError(
            f"{path}: BVH input is not supported yet (no BVH reader); render keyframes.json"
        )
    motion = reader(Path(path))
    if not all(
        hasattr(motion, a) for a in ("names", "nframes", "frame_time", "forward_kinematics")
    ):
        raise RenderError(f"{path}: BVH input is not supported yet (unknown reader result)")
    if motion.nframes < 1:
        raise RenderError(f"{path}: expected at least one frame, got none")
    index = _bvh_index(skel, motion.names, path)
    scale = _bvh_scale(skel, motion.forward_kinematics(None)[0], index)
    count = min(MAX_BVH_PANELS, motion.nframes)
    poses = []
    for f in np.unique(np.linspace(0, motion.nframes - 1, count).round().astype(int)):
        heads, world = motion.forward_kinematics(int(f))
        head, rot = heads[index] * scale, quat.normalize(world[index])
        tail = head + quat.rotate(rot, skel.tail0 - skel.head0)
        poses.append(Pose(head, tail, rot, f"frame {f + 1}", f * float(motion.frame_time)))
    return poses


def key_poses(path: Path, kind: str, skel: Skeleton) -> list[Pose]:
    """The poses of a keyframes.json or BVH file (``kind`` from :func:`input_kind`)."""
    if kind == "bvh":
        return bvh_poses(path, skel)
    keys = read_keyframes(Path(path))[1]
    if not keys:
        raise RenderError(f"{path}: expected at least one key, got none")
    return poses_from_keys(skel, keys)


def _vec(d: dict, keys: str = "xyz") -> list[float]:
    values = [float(d[k]) for k in keys]
    if not all(abs(v) <= LARGEST for v in values):  # NaN fails too
        raise ValueError(f"expected finite numbers, got {shown(values)}")
    return values


def _tf_pose(msg: dict) -> tuple[list[str], np.ndarray, np.ndarray]:
    """(bone names, heads (n,3), world rotations (n,4) w-first) from a /tf message."""
    frames: dict[str, tuple[np.ndarray, np.ndarray]] = {PUPPET_FRAME: (np.zeros(3), quat.IDENTITY)}
    names = []
    for t in msg["transforms"]:
        if t["parent_frame_id"] not in frames:
            continue  # world → puppet: the Z-up display frame, not part of the doll
        head_p, q_p = frames[t["parent_frame_id"]]
        r = t["rotation"]
        q_rel = np.array(_vec(r, "wxyz"))
        head = head_p + quat.rotate(q_p, np.array(_vec(t["translation"])))
        frames[t["child_frame_id"]] = (head, quat.normalize(quat.mul(q_p, q_rel)))
        names.append(t["child_frame_id"])
    return names, np.array([frames[n][0] for n in names]), np.array([frames[n][1] for n in names])


def _order(skel: Skeleton, names: list[str], where: str) -> np.ndarray:
    """Indices into ``names`` of the skeleton's bones, in skeleton order."""
    index = {n: i for i, n in enumerate(names)}
    missing = [n for n in skel.names if n not in index]
    if missing:
        raise RenderError(f"{where}: expected every bone of the rig, got no bone {missing[0]!r}")
    return np.array([index[n] for n in skel.names])


def _pointer(msg: dict | None) -> dict:
    """Pose fields of the pointer (centre, radius, grip point) from a /puppet/pointer message."""
    if msg is None or not msg["entities"]:
        return {}
    entity = msg["entities"][0]
    if not entity["spheres"]:
        return {}
    sphere = entity["spheres"][0]
    out = {
        "pointer": np.array(_vec(sphere["pose"]["position"])),
        "pointer_radius": 0.5 * float(sphere["size"]["x"]),
    }
    if entity["lines"] and len(entity["lines"][0]["points"]) >= 2:
        out["grip"] = np.array(_vec(entity["lines"][0]["points"][1]))
    return out


def _step_pose(
    skel: Skeleton, bones: dict, tf: dict | None, pointer: dict | None, ns: int, where: str
) -> Pose:
    """One recorded step as a :class:`Pose` in the skeleton's bone order."""
    points = bones["entities"][0]["lines"][0]["points"]
    seg = np.array([_vec(p) for p in points]).reshape(-1, 2, 3)
    if tf is not None:
        names, _, rot = _tf_pose(tf)
        order = _order(skel, names, where)
        rot = rot[order]
    else:
        order = np.arange(len(skel.names))
    if len(seg) < len(order) or np.max(order, initial=-1) >= len(seg):
        raise RenderError(f"{where}: expected {len(order)} bone segments, got {len(seg)}")
    head, tail = seg[order, 0], seg[order, 1]
    if tf is None:
        rest = skel.tail0 - skel.head0
        rot = np.array([_arc(a, b) for a, b in zip(rest, tail - head, strict=True)])
    pose = Pose(head, tail, rot, "", ns / 1e9, **_pointer(pointer))
    values = [pose.head, pose.tail, pose.rot, pose.pointer, pose.grip, pose.pointer_radius]
    for value in values:
        if value is not None and not np.all(np.abs(value) <= LARGEST):  # NaN fails too
            raise RenderError(f"{where}: expected finite coordinates, got {shown(value)}")
    return pose


def _arc(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    if np.linalg.norm(a) < 1e-12 or np.linalg.norm(b) < 1e-12:
        return quat.IDENTITY.copy()
    return quat.from_two_vectors(a, b)


def trace_poses(path: Path, skel: Skeleton) -> tuple[list[Pose], list[Pose]]:
    """(every recorded step, the key moments) of a trace, as poses."""
    data = read_trace(Path(path))
    bones = data.get("/puppet/bones") or []
    if not bones:
        raise RenderError(f"{path}: expected /puppet/bones messages, got none")
    tf, pointer = dict(data.get("/tf", [])), dict(data.get("/puppet/pointer", []))
    steps = []
    for ns, msg in bones:
        where = f"{path}: /puppet/bones at {ns / 1e9:.6g} s"
        try:
            steps.append(_step_pose(skel, msg, tf.get(ns), pointer.get(ns), ns, where))
        except (KeyError, TypeError, IndexError, ValueError) as exc:
            raise RenderError(
                f"{where}: expected bone line segments and transforms, got "
                f"a malformed message ({type(exc).__name__}: {exc})"
            ) from exc
    return steps, _key_moments(steps, data.get("/puppet/keyframe", []))


def _key_moments(steps: list[Pose], events: list[tuple[int, dict]]) -> list[Pose]:
    """The step nearest each key event, labelled; without events, evenly spaced steps."""
    if not events:
        picks = np.unique(np.linspace(0, len(steps) - 1, min(SAMPLED_PANELS, len(steps))).round())
        return [steps[int(i)] for i in picks]
    times = [p.time for p in steps]
    out = []
    for ns, event in events:
        if isinstance(event, dict) and event.get("undo") is True:
            del out[-1:]  # the latest key was dropped
            continue
        t = ns / 1e9
        j = bisect.bisect_left(times, t)
        near = [k for k in (j - 1, j) if 0 <= k < len(steps)]
        k = min(near, key=lambda k: abs(times[k] - t))
        label = str(event.get("label", "")) if isinstance(event, dict) else ""
        out.append(replace(steps[k], label=label))
    return out
