"""Test helpers for the BVH tests, made by code rather than stored files.

* Skeletons like the ones users bring: CMU-like (31 joints, zero-length
  LHipJoint/RHipJoint, ZYX), Mixamo-like (65 joints, ``mixamorig:`` names, cm,
  ZYX, ``*_End`` joints) and a 19-joint one in metres with a non-zero root offset.
* ``bvh_text``: a BVH writer that shares no code with puppetcli's.
* ``independent_fk``: joint world positions of a BVH file from the third-party
  ``bvh`` package's parse (float64) and 4×4 matrices built with scipy, sharing
  no code with puppetcli's reader or writer.
* ``rigid_keys``: keyframes whose heads follow exactly from their local rotations.
"""

from __future__ import annotations

from dataclasses import dataclass

import bvh as bvh_package
import numpy as np
from scipy.spatial.transform import Rotation

from puppetcli.rig.skeleton import Skeleton
from puppetcli.run.keyframes import BonePose, Keyframe
from solver import quat

ORDERS = ("XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX")


@dataclass
class J:
    """A joint of a test skeleton: offset from its parent, optional End Site offset."""

    name: str
    parent: str | None
    offset: tuple[float, float, float]
    end: tuple[float, float, float] | None = None


def _mirror(joints: list[J], left: str, right: str) -> list[J]:
    """The right side of a skeleton from its left side: names swapped, x negated."""
    out = []
    for j in joints:
        end = None if j.end is None else (-j.end[0], j.end[1], j.end[2])
        parent = j.parent.replace(left, right) if j.parent and left in j.parent else j.parent
        out.append(J(j.name.replace(left, right), parent, (-j.offset[0], *j.offset[1:]), end))
    return out


def cmu_like() -> list[J]:
    """31 joints in CMU units (× 0.056444 = m); LHipJoint/RHipJoint/LThumb/shoulders at 0."""
    left = [
        J("LHipJoint", "Hips", (0, 0, 0)),
        J("LeftUpLeg", "LHipJoint", (1.36, -1.8, 0.84)),
        J("LeftLeg", "LeftUpLeg", (2.44, -6.7, 0)),
        J("LeftFoot", "LeftLeg", (2.6, -7.1, 0)),
        J("LeftToeBase", "LeftFoot", (0.16, -0.44, 2.1), end=(0, 0, 1.1)),
        J("LeftShoulder", "Spine1", (0, 0, 0)),
        J("LeftArm", "LeftShoulder", (3.4, 0.1, 0)),
        J("LeftForeArm", "LeftArm", (5.3, 0, 0)),
        J("LeftHand", "LeftForeArm", (3.6, 0, 0)),
        J("LeftFingerBase", "LeftHand", (0.7, 0, 0)),
        J("LeftHandIndex1", "LeftFingerBase", (0.6, 0, 0), end=(0.6, 0, 0)),
        J("LThumb", "LeftHand", (0, 0, 0), end=(0.5, 0, 0.5)),
    ]
    right = _mirror(left, "Left", "Right")
    for j in right:
        j.name = j.name.replace("LHip", "RHip").replace("LThumb", "RThumb")
        j.parent = j.parent.replace("LHip", "RHip") if j.parent else None
    spine = [
        J("LowerBack", "Hips", (0, 2.0, -0.05)),
        J("Spine", "LowerBack", (0, 2.07, -0.1)),
        J("Spine1", "Spine", (0, 2.07, 0)),
        J("Neck", "Spine1", (0, 1.9, 0)),
        J("Neck1", "Neck", (0, 1.0, 0)),
        J("Head", "Neck1", (0, 1.0, 0), end=(0, 1.0, 0)),
    ]
    return [J("Hips", None, (0, 0, 0)), *left[:5], *right[:5], *spine, *left[5:], *right[5:]]


def mixamo_like() -> list[J]:
    """65 joints in centimetres with ``mixamorig:`` names and zero-length ``*_End`` joints."""
    joints = [
        J("Hips", None, (0, 0, 0)),
        J("Spine", "Hips", (0, 10, 0)),
        J("Spine1", "Spine", (0, 12, 0)),
        J("Spine2", "Spine1", (0, 13, 0)),
        J("Neck", "Spine2", (0, 15, 0)),
        J("Head", "Neck", (0, 10, 0)),
        J("HeadTop_End", "Head", (0, 18, 0), end=(0, 0, 0)),
    ]
    arm = [
        J("LeftShoulder", "Spine2", (6, 10, 0)),
        J("LeftArm", "LeftShoulder", (12, 0, 0)),
        J("LeftForeArm", "LeftArm", (27, 0, 0)),
        J("LeftHand", "LeftForeArm", (27, 0, 0)),
    ]
    bases = {"Thumb": (3, -1, 3), "Index": (9, 0, 2.5), "Middle": (9.5, 0, 0.5)}
    bases |= {"Ring": (9, 0, -1.5), "Pinky": (8, 0, -3.5)}
    for finger, base in bases.items():
        parent = "LeftHand"
        for k, offset in enumerate((base, (3.5, 0, 0), (2.5, 0, 0), (2, 0, 0)), start=1):
            name = f"LeftHand{finger}{k}"
            arm.append(J(name, parent, offset, end=(0, 0, 0) if k == 4 else None))
            parent = name
    leg = [
        J("LeftUpLeg", "Hips", (9, -7, 0)),
        J("LeftLeg", "LeftUpLeg", (0, -42, 0)),
        J("LeftFoot", "LeftLeg", (0, -42, 0)),
        J("LeftToeBase", "LeftFoot", (0, -8, 12)),
        J("LeftToe_End", "LeftToeBase", (0, 0, 8), end=(0, 0, 0)),
    ]
    joints += arm + _mirror(arm, "Left", "Right") + leg + _mirror(leg, "Left", "Right")
    for j in joints:
        j.name = "mixamorig:" + j.name
        j.parent = "mixamorig:" + j.parent if j.parent else None
    return joints


def simple19() -> list[J]:
    """19 joints in metres, the root 0.95 m up (a non-zero root OFFSET)."""
    left = [
        J("LShoulder", "Chest", (0.05, 0.2, 0)),
        J("LArm", "LShoulder", (0.13, 0, 0)),
        J("LForearm", "LArm", (0.28, 0, 0)),
        J("LHand", "LForearm", (0.25, 0, 0), end=(0.18, 0, 0)),
        J("LThigh", "Hips", (0.1, -0.05, 0)),
        J("LShin", "LThigh", (0, -0.42, 0)),
        J("LFoot", "LShin", (0, -0.42, 0), end=(0, -0.05, 0.15)),
    ]
    spine = [
        J("Hips", None, (0, 0.95, 0)),
        J("Spine", "Hips", (0, 0.1, 0)),
        J("Chest", "Spine", (0, 0.2, 0)),
        J("Neck", "Chest", (0, 0.25, 0)),
        J("Head", "Neck", (0, 0.1, 0), end=(0, 0.2, 0)),
    ]
    return spine + left + _mirror(left, "L", "R")


SKELETONS = {"cmu31": cmu_like, "mixamo65": mixamo_like, "simple19": simple19}


def _ordered(joints: list[J]) -> list[J]:
    """Depth first from the root, children in list order (BVH's channel order)."""
    out: list[J] = []

    def visit(name: str | None) -> None:
        for j in joints:
            if j.parent == name:
                out.append(j)
                visit(j.name)

    visit(None)
    return out


def channel_lists(joints: list[J], orders: list[str], root_positions: bool = True) -> dict:
    """Channels per joint name: the root gets X/Y/Z positions first, then rotations."""
    out = {}
    for j, order in zip(_ordered(joints), orders, strict=True):
        rot = [f"{a}rotation" for a in order]
        pos = ["Xposition", "Yposition", "Zposition"] if j.parent is None and root_positions else []
        out[j.name] = pos + rot
    return out


def random_frames(joints: list[J], channels: dict, n: int, seed: int, spread=40.0) -> np.ndarray:
    """(n, nchannels): angles uniform in ±spread degrees, positions near the OFFSET."""
    rng = np.random.default_rng(seed)
    columns = []
    for j in _ordered(joints):
        for c in channels[j.name]:
            if c.endswith("position"):
                base = j.offset["XYZ".index(c[0])]
                columns.append(base + rng.uniform(-1.0, 1.0, n))
            else:
                columns.append(rng.uniform(-spread, spread, n))
    return np.array(columns).T.reshape(n, -1)


def bvh_text(joints, channels, frames, frame_time=1 / 30, newline="\n", indent="\t") -> str:
    """A BVH file written independently of puppetcli (17 significant digits)."""
    lines = ["HIERARCHY"]

    def block(j: J, depth: int) -> None:
        pad = indent * depth
        lines.append(f"{pad}{'ROOT' if j.parent is None else 'JOINT'} {j.name}")
        lines.append(pad + "{")
        lines.append(f"{pad}{indent}OFFSET " + " ".join(f"{x:.17g}" for x in j.offset))
        chans = channels[j.name]
        lines.append(f"{pad}{indent}CHANNELS {len(chans)} {' '.join(chans)}")
        for child in (c for c in joints if c.parent == j.name):
            block(child, depth + 1)
        if j.end is not None:
            lines.extend([f"{pad}{indent}End Site", f"{pad}{indent}{{"])
            lines.append(f"{pad}{indent * 2}OFFSET " + " ".join(f"{x:.17g}" for x in j.end))
            lines.append(f"{pad}{indent}}}")
        lines.append(pad + "}")

    block(_ordered(joints)[0], 0)
    lines += ["MOTION", f"Frames: {len(frames)}", f"Frame Time: {frame_time:.17g}"]
    lines += [" ".join(f"{x:.17g}" for x in row) for row in frames]
    return newline.join(lines) + newline


def make_bvh(kind: str, order: str = "ZYX", frames: int = 3, seed: int = 0, **kw) -> str:
    """A test skeleton's BVH text; ``order`` may be ``"mixed"`` (a seeded order per joint)."""
    joints = SKELETONS[kind]()
    rng = np.random.default_rng(seed + 1)
    n = len(joints)
    orders = [ORDERS[k] for k in rng.integers(0, 6, n)] if order == "mixed" else [order] * n
    channels = channel_lists(joints, orders)
    return bvh_text(joints, channels, random_frames(joints, channels, frames, seed), **kw)


def independent_fk(text: str) -> tuple[list[str], list[int], np.ndarray]:
    """(names, parent indices, joint world positions (nframes, nj, 3)) of BVH ``text``.

    Parsed by the ``bvh`` package; W_j = W_parent · [R_j t_j; 0 1] with R_j =
    scipy ``from_euler`` of the rotation channels in file order (intrinsic,
    upper case) and t_j the OFFSET with position channels replacing components.
    """
    mocap = bvh_package.Bvh(text)
    names = mocap.get_joints_names()
    parents = [mocap.joint_parent_index(n) for n in names]
    starts = [mocap.get_joint_channels_index(n) for n in names]
    channels = [mocap.joint_channels(n) for n in names]
    offsets = [np.array(mocap.joint_offset(n)) for n in names]
    out = np.zeros((len(mocap.frames), len(names), 3))
    for f, row in enumerate(mocap.frames):
        values = [float(v) for v in row]
        world: list[np.ndarray] = []
        for i in range(len(names)):
            t = offsets[i].copy()
            axes, angles = "", []
            for k, c in enumerate(channels[i]):
                if c.endswith("position"):
                    t["XYZ".index(c[0])] = values[starts[i] + k]
                else:
                    axes += c[0]
                    angles.append(values[starts[i] + k])
            m = np.eye(4)
            if axes:
                m[:3, :3] = Rotation.from_euler(axes, angles, degrees=True).as_matrix()
            m[:3, 3] = t
            world.append(m if parents[i] < 0 else world[parents[i]] @ m)
            out[f, i] = world[i][:3, 3]
    return names, parents, out


def rigid_keys(skel: Skeleton, local: np.ndarray, root: np.ndarray, times=None) -> list[Keyframe]:
    """Keys from local rotations (nkeys, nb, 4) and root heads (nkeys, 3): world q_b =
    q_parent ⊗ local_b, head_b = head_parent + q_parent · (head0_b − head0_parent)."""
    keys = []
    for k in range(local.shape[0]):
        world = np.zeros_like(local[k])
        head = np.zeros((len(skel.names), 3))
        for b, p in enumerate(skel.parents):
            if p < 0:
                world[b], head[b] = local[k, b], root[k]
            else:
                world[b] = quat.mul(world[p], local[k, b])
                head[b] = head[p] + quat.rotate(world[p], skel.head0[b] - skel.head0[p])
        bones = {
            n: BonePose(head=head[b], rotation=world[b], local=local[k, b])
            for b, n in enumerate(skel.names)
        }
        t = float(k) if times is None else float(times[k])
        keys.append(Keyframe(time=t, label=f"key {k}", bones=bones))
    return keys


def random_quats(n: int, rng: np.random.Generator) -> np.ndarray:
    """n random unit quaternions (w, x, y, z), uniform on SO(3)."""
    q = rng.normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def test_skeleton_sizes() -> None:
    """The generated skeletons have the joint counts the rig tests rely on."""
    assert [len(SKELETONS[k]()) for k in ("simple19", "cmu31", "mixamo65")] == [19, 31, 65]
    names, parents, _ = independent_fk(make_bvh("cmu31"))
    assert names[0] == "Hips" and parents[0] == -1 and len(set(names)) == 31
