"""What ``puppetcli render`` can draw: poses from keyframes.json, a BVH file, a trace or a rig.

- ``keyframes.json``: one pose per key (``puppetcli.rig.skeleton.key_pose``).
- ``.bvh``: its frames drawn on the rig (``puppetcli.render.motion``: the rig's
  rest pose is found among the file's rest pose and frames, the motion scaled to
  the rig and set on its ground); without ``--rig`` on ``rig from-bvh``'s rig of
  the file, its unit inferred.  At most ``MAX_PANELS`` frames, evenly spaced,
  make a sheet, or the frames asked for.
- ``.glb``/``.gltf``: the same for the first skin and its first animation (one
  frame per key marker or key time), without ``--rig`` on ``rig from-gltf``'s rig.
- ``trace.mcap``: one pose per recorded step.  Head and tail of every bone come
  from the ``/puppet/bones`` line list (in the ``/tf`` bone order), the bone
  rotations from ``/tf`` (composed down the tree; without ``/tf``, the shortest
  arc from the rest axis, which loses a box's twist), the pointer and its
  coupling line from ``/puppet/pointer``.  Key moments are the
  ``/puppet/keyframe`` events, each shown with the recorded step nearest to it (an
  ``undo`` event drops the latest).
- a rig ``.yaml``: its rest pose.

keyframes.json and traces need the rig (``--rig``) for bone shapes, props and
the ground.
"""

from __future__ import annotations

import bisect
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from puppetcli.bvh.model import Bvh, forward_kinematics
from puppetcli.bvh.read import read_bvh
from puppetcli.bvh.rig import rig_text_from_bvh
from puppetcli.bvh.units import infer_unit
from puppetcli.errors import shown
from puppetcli.gltf.read import Gltf, quat_from_matrix, read_gltf, skin_joints
from puppetcli.gltf.rig import rig_text_from_gltf
from puppetcli.mcap.trace import PUPPET_FRAME, read_trace
from puppetcli.render.camera import RenderError
from puppetcli.render.motion import Motion, motion_poses
from puppetcli.render.picture import Pose, poses_from_keys
from puppetcli.rig.load import load_rig, rig_from_text
from puppetcli.rig.skeleton import Skeleton
from puppetcli.run.keyframes import read_keyframes
from puppetcli.yamldoc import LARGEST
from solver import quat
from solver.spec import RigSpec

__all__ = [
    "INPUT_KINDS", "OWN_SKELETON", "file_rig", "input_kind", "key_poses", "read_own",
    "trace_poses",
]  # fmt: skip

INPUT_KINDS = {".json": "keyframes", ".bvh": "bvh", ".glb": "gltf", ".gltf": "gltf",
               ".mcap": "trace", ".yaml": "rig", ".yml": "rig"}  # fmt: skip
OWN_SKELETON = ("bvh", "gltf", "rig")  # kinds that need no --rig
SAMPLED_PANELS = 9  # panels of a sheet of a trace without key events


def input_kind(path: Path) -> str:
    """``keyframes``, ``bvh`` or ``trace``, from the file name's suffix."""
    kind = INPUT_KINDS.get(Path(path).suffix.lower())
    if kind is None:
        raise RenderError(
            f"{path}: expected keyframes.json, a .bvh or .glb file, a trace .mcap or a rig .yaml, "
            f"got a {Path(path).suffix or 'suffix-less'} file"
        )
    return kind


def read_own(path: Path, kind: str) -> Bvh | Gltf | None:
    """A BVH or glTF file read once, for both its rig and its poses (None for other kinds)."""
    if kind == "bvh":
        return read_bvh(Path(path))
    return read_gltf(Path(path)) if kind == "gltf" else None


def bvh_motion(bvh: Bvh) -> Motion:
    """Every frame of a BVH file as a :class:`Motion` (frame f labelled ``frame f``, as
    ``rig from-bvh --frame f`` counts them)."""
    rest_heads, rest_rots = bvh.forward_kinematics(None)
    trans, rot = bvh.poses()
    heads, rots = forward_kinematics(bvh.parents, trans, rot)
    nf = bvh.nframes
    return Motion(bvh.names, bvh.parents, rest_heads, rest_rots, heads, rots,
                  np.arange(nf) * float(bvh.frame_time), tuple(f"frame {f}" for f in range(nf)),
                  bvh.source)  # fmt: skip


def gltf_motion(g: Gltf) -> Motion:
    """The first animation of a glTF file's first skin as a :class:`Motion`: one frame per
    key marker (a puppetcli export) or per key time of the animation; the bind pose alone
    when the file has no animation."""
    joints = skin_joints(g, 0)
    rest_rots = quat_from_matrix(joints.bind)
    if not g.doc.animations:
        times, labels = np.zeros(1), ("rest",)
        worlds = [g.world()]
    else:
        markers = (g.doc.animations[0].extras or {}).get("markers")
        if isinstance(markers, list) and markers and all(_is_marker(m) for m in markers):
            times = np.array([float(m["time"]) for m in markers])
            labels = tuple(str(m.get("label", "")) for m in markers)
        else:
            times = g.animation_times(0)
            labels = tuple(f"{t:.3f} s" for t in times)
        worlds = [g.world(g.sample(0, float(t))) for t in times]
    world = np.array(worlds)[:, joints.nodes]
    return Motion(joints.names, joints.parents, joints.bind[:, :3, 3], rest_rots,
                  world[..., :3, 3], quat_from_matrix(world), times, labels, g.source)  # fmt: skip


def _is_marker(m: object) -> bool:
    t = m.get("time") if isinstance(m, dict) else None
    return isinstance(t, (int, float)) and abs(t) <= LARGEST  # NaN fails too


def file_rig(
    path: Path, kind: str, say: Callable[[str], None], parsed: Bvh | Gltf | None = None
) -> RigSpec:
    """The rig of a file that carries its own skeleton: a BVH file (``rig from-bvh``'s rig,
    its unit inferred), a glTF file (``rig from-gltf``'s) or a rig file itself; ``parsed``:
    the file as ``read_own`` read it, if it was."""
    if kind == "rig":
        return load_rig(Path(path))
    parsed = parsed or read_own(path, kind)
    if kind == "gltf":
        g = parsed
        text = rig_text_from_gltf(g, 0, Path(path).stem, "", str(Path(path).resolve()))
        return rig_from_text(text, f"<rig of {path}>")
    bvh = parsed
    unit = infer_unit(bvh)
    say(f"note: {path}: {unit.note()}")
    if unit.warning:
        say(f"warning: {path}: {unit.warning}")
    return rig_from_text(rig_text_from_bvh(bvh, Path(path).stem, unit.scale), f"<rig of {path}>")


def key_poses(
    path: Path,
    kind: str,
    skel: Skeleton,
    spec: RigSpec,
    frames: Sequence[int] = (),
    say: Callable[[str], None] = lambda line: None,
    parsed: Bvh | Gltf | None = None,
) -> list[Pose]:
    """The poses of a keyframes.json, BVH, glTF or rig file (``kind`` from
    :func:`input_kind`); ``frames`` picks a BVH or glTF file's frames; ``parsed``: the file
    as ``read_own`` read it, if it was."""
    if kind in ("bvh", "gltf"):
        parsed = parsed or read_own(path, kind)
        motion = bvh_motion(parsed) if kind == "bvh" else gltf_motion(parsed)
        return motion_poses(motion, skel, spec, frames, say)
    if kind == "rig":
        rest = np.tile(quat.IDENTITY, (len(skel.names), 1))
        return [Pose(skel.head0, skel.tail0, rest, "rest", 0.0)]
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
