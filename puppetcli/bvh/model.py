"""BVH (Biovision Hierarchy) skeletons and motions: the types and their maths.

Reading is in ``puppetcli.bvh.read``, writing in ``puppetcli.bvh.write``; the
file format and our choices are in ``docs/bvh.md``.

Rotation channels.  Degrees.  The rotation channels of a joint, in the order
listed, are *intrinsic* elemental rotations: ``CHANNELS 3 Zrotation Xrotation
Yrotation`` means R = Rz(z)·Rx(x)·Ry(y) for column vectors, i.e. the quaternion
q = q_z ⊗ q_x ⊗ q_y (scipy's ``from_euler("ZXY", [z, x, y])``, upper case =
intrinsic).

Forward kinematics (4×4 transforms, column vectors)::

    W_root = T(t_root)·R_root,    W_j = W_parent·T(t_j)·R_j

t_j is the joint's OFFSET (in its parent's frame); position channels *replace*
the matching OFFSET component (as Blender, bvhio and pybvh read them), for the
root and for any other joint that has them.  A joint's world position is the
translation of W_j; an End Site lies at W_j·OFFSET_end.

Our rigs.  A bone's rest frame is world-aligned and hangs from its parent at
its head, so the BVH rest pose (every channel 0) *is* the rig's rest pose,
OFFSET = child head − parent head, and a joint's R_j is the keyframes' "local"
rotation q_parent⁻¹ ⊗ q_child (the root's: its world rotation).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from puppetcli.errors import PuppetError
from solver import quat

__all__ = [
    "CHANNEL_NAMES",
    "ORDERS",
    "Bvh",
    "BvhError",
    "BvhJoint",
    "euler_from_quat",
    "forward_kinematics",
    "quat_from_euler",
    "unwrap_euler",
]

ORDERS = ("XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX")  # the six Tait–Bryan orders
POSITIONS = ("Xposition", "Yposition", "Zposition")
ROTATIONS = ("Xrotation", "Yrotation", "Zrotation")
CHANNEL_NAMES = POSITIONS + ROTATIONS


class BvhError(PuppetError):
    """A BVH file is unreadable or malformed (``<file>:<line>: expected …, got …``)."""


@dataclass(frozen=True)
class BvhJoint:
    """One ROOT or JOINT: name; parent index (−1 for the root); offset (3,) file units;
    channels in file order (``Xposition`` … ``Zrotation``); ends: End Site offsets
    (each (3,), usually zero or one); line: 1-based line of its ROOT/JOINT keyword."""

    name: str
    parent: int
    offset: np.ndarray
    channels: tuple[str, ...]
    ends: tuple[np.ndarray, ...] = ()
    line: int = 0

    @property
    def rotation_order(self) -> str:
        """The rotation axes in channel order, e.g. ``"ZXY"`` (may be shorter than 3)."""
        return "".join(c[0] for c in self.channels if c in ROTATIONS)


@dataclass(frozen=True)
class Bvh:
    """A parsed BVH file.  joints: depth-first (parents before children);
    frames (nframes, nchannels): channel values in file order (positions in file
    units, rotations in degrees); frame_time: seconds per frame; source: file name."""

    joints: tuple[BvhJoint, ...]
    frames: np.ndarray
    frame_time: float
    source: str = "<bvh>"

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(j.name for j in self.joints)

    @property
    def parents(self) -> np.ndarray:
        return np.array([j.parent for j in self.joints], dtype=np.int64)

    @property
    def nframes(self) -> int:
        return int(self.frames.shape[0])

    def channel_starts(self) -> np.ndarray:
        """Index of each joint's first channel in a frame line, (njoint,)."""
        counts = [len(j.channels) for j in self.joints]
        return np.concatenate(([0], np.cumsum(counts)[:-1])).astype(np.int64)

    def pose(self, frame: int | None) -> tuple[np.ndarray, np.ndarray]:
        """(translations (nj,3) file units, local rotations (nj,4)) at ``frame``.

        ``frame=None`` is the rest pose: offsets and identity rotations (the
        position channels are ignored, so the root sits at its OFFSET).
        """
        if frame is None:
            offsets = np.array([j.offset for j in self.joints], dtype=float).reshape(-1, 3)
            return offsets, np.tile(quat.IDENTITY, (len(self.joints), 1))
        trans, rot = self.poses(self.frames[frame : frame + 1])
        return trans[0], rot[0]

    def poses(self, values: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(translations (nf,nj,3), local rotations (nf,nj,4)) of frame lines ``values``
        (nf, nchannels); every frame of the file when ``values`` is None."""
        values = self.frames if values is None else np.asarray(values, dtype=float)
        nf = values.shape[0]
        trans = np.tile(np.array([j.offset for j in self.joints], dtype=float), (nf, 1, 1))
        rot = np.tile(quat.IDENTITY, (nf, len(self.joints), 1))
        for i, (joint, start) in enumerate(zip(self.joints, self.channel_starts(), strict=True)):
            columns = start + np.arange(len(joint.channels))
            angles = [k for k, c in zip(columns, joint.channels, strict=True) if c in ROTATIONS]
            for k, c in zip(columns, joint.channels, strict=True):
                if c in POSITIONS:
                    trans[:, i, POSITIONS.index(c)] = values[:, k]
            if angles:
                rot[:, i] = quat_from_euler(values[:, angles], joint.rotation_order)
        return trans, rot

    def forward_kinematics(self, frame: int | None) -> tuple[np.ndarray, np.ndarray]:
        """(joint world positions (nj,3) file units, world rotations (nj,4)) at ``frame``."""
        trans, rot = self.pose(frame)
        return forward_kinematics(self.parents, trans, rot)

    def end_sites(self, heads: np.ndarray, world: np.ndarray) -> list[np.ndarray]:
        """World positions of every joint's End Sites, (nends,3) per joint."""
        return [
            heads[i] + quat.rotate(world[i], np.array(j.ends, dtype=float).reshape(-1, 3))
            for i, j in enumerate(self.joints)
        ]


def forward_kinematics(
    parents: np.ndarray, trans: np.ndarray, rot: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Heads p_j = p_parent + q_parent·t_j and world rotations q_j = q_parent ⊗ r_j.

    ``parents`` must list parents before children; a root (−1) has p = t, q = r.
    Works on (nj,3)/(nj,4) or, with leading frame axes, (…, nj, 3)/(…, nj, 4).
    """
    heads = np.array(trans, dtype=float)
    world = np.array(rot, dtype=float)
    for j, p in enumerate(parents):
        if p >= 0:
            heads[..., j, :] = heads[..., p, :] + quat.rotate(world[..., p, :], trans[..., j, :])
            world[..., j, :] = quat.mul(world[..., p, :], rot[..., j, :])
    return heads, world


def quat_from_euler(angles: np.ndarray, order: str) -> np.ndarray:
    """Unit quaternions (n,4) of intrinsic rotations ``angles`` (n, len(order)) in degrees:
    q = q_first ⊗ q_second ⊗ q_third, each about its axis."""
    half = np.radians(np.asarray(angles, dtype=float).reshape(-1, len(order))) / 2.0
    q = np.tile(quat.IDENTITY, (len(half), 1))
    for k, axis in enumerate(order.upper()):
        elemental = np.zeros((len(half), 4))
        elemental[:, 0] = np.cos(half[:, k])
        elemental[:, 1 + "XYZ".index(axis)] = np.sin(half[:, k])
        q = quat.mul(q, elemental)
    return q


LOCKED = float(np.sqrt(np.finfo(float).eps))  # |cos b| below this: gimbal lock


def euler_from_quat(q: np.ndarray, order: str) -> np.ndarray:
    """Intrinsic Tait–Bryan angles (n,3) in degrees of unit quaternions (n,4), in ``order``.

    For R = R_i(a)·R_j(b)·R_k(c) (axes i, j, k of ``order``, s = +1 for a cyclic order,
    −1 otherwise): sin b = s·R_ik, tan a = −s·R_jk / R_kk, tan c = −s·R_ij / R_ii, b from
    atan2 so it stays accurate near ±90°.  The first and third angles are in
    (−180°, 180°], the middle one in [−90°, 90°] (scipy's ``as_euler`` convention, which
    tests/puppetcli/bvh/test_bvh_read.py checks this against).  At gimbal lock only a ± c is
    defined: c is set to 0.  "Locked" is |cos b| below √ε ≈ 1.5e-8: treating a nearly
    locked rotation as locked errs by about cos b, computing a and c from entries of size
    cos b errs by about ε / cos b, so the threshold √ε keeps both below ~1.5e-8 rad (with
    1e-12, a rotation 1e-10 from lock came back 4e-6 rad off).  Written out rather than
    scipy's because importing scipy.spatial costs a third of a second of every pose.
    """
    i, j, k = ("XYZ".index(axis) for axis in order.upper())
    s = 1.0 if (i, j, k) in ((0, 1, 2), (1, 2, 0), (2, 0, 1)) else -1.0
    r = quat.matrix(quat.normalize(np.asarray(q, dtype=float).reshape(-1, 4)))
    cos_b = np.hypot(r[:, i, i], r[:, i, j])
    b = np.arctan2(s * r[:, i, k], cos_b)
    locked = cos_b < LOCKED
    a = np.where(
        locked,
        np.arctan2(s * r[:, k, j], r[:, j, j]),
        np.arctan2(-s * r[:, j, k], r[:, k, k]),
    )
    c = np.where(locked, 0.0, np.arctan2(-s * r[:, i, j], r[:, i, i]))
    return np.degrees(np.stack((a, b, c), axis=1))


def unwrap_euler(angles: np.ndarray) -> np.ndarray:
    """Make Euler triples (nframes, …, 3) continuous from frame to frame.

    A Tait–Bryan rotation has two triples, (a, b, c) and (a + 180°, 180° − b,
    c + 180°), and each angle is defined up to 360°.  Frame 0 is kept; every
    later frame takes, of both triples and every 360° shift per angle, the one
    closest to the previous frame (sum of squared differences), as Blender's
    exporter does with its compatibility hint.
    """
    out = np.array(angles, dtype=float)
    flip = np.array([180.0, 180.0, 180.0])
    sign = np.array([1.0, -1.0, 1.0])
    for f in range(1, out.shape[0]):
        prev = out[f - 1]
        first = _nearest_turn(out[f], prev)
        second = _nearest_turn(out[f] * sign + flip, prev)
        closer = np.sum((second - prev) ** 2, axis=-1) < np.sum((first - prev) ** 2, axis=-1)
        out[f] = np.where(closer[..., None], second, first)
    return out


def _nearest_turn(angles: np.ndarray, target: np.ndarray) -> np.ndarray:
    """``angles`` shifted by whole turns (360°) to lie within 180° of ``target``."""
    return angles + 360.0 * np.round((target - angles) / 360.0)
