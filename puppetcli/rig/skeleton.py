"""A rig's skeleton as exporters and renderers need it, and bone poses from keyframes.

Bones are in rig order (parents first).  Rest frames are world-aligned, so a
bone's world pose in a key is: head = key head, orientation = key rotation, and
its tail = head + rotation · (tail0 − head0).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from puppetcli.run.keyframes import Keyframe
from solver import quat
from solver.spec import RigSpec


@dataclass(frozen=True)
class Skeleton:
    """names (nb,); parents (nb,) index or -1; head0, tail0 (nb,3) m rest pose;
    shape (nb,) "capsule" | "sphere" | "box"; radius (nb,) m; half (nb,3) box half sizes (m)."""

    names: tuple[str, ...]
    parents: np.ndarray
    head0: np.ndarray
    tail0: np.ndarray
    shape: tuple[str, ...]
    radius: np.ndarray
    half: np.ndarray

    @classmethod
    def from_spec(cls, spec: RigSpec) -> Skeleton:
        index = {b.name: i for i, b in enumerate(spec.bones)}
        return cls(
            names=tuple(b.name for b in spec.bones),
            parents=np.array([index[b.parent] if b.parent else -1 for b in spec.bones]),
            head0=np.array([b.head for b in spec.bones], dtype=float),
            tail0=np.array([b.tail for b in spec.bones], dtype=float),
            shape=tuple(b.shape.kind for b in spec.bones),
            radius=np.array([b.shape.radius for b in spec.bones], dtype=float),
            half=np.array([b.shape.half_extents for b in spec.bones], dtype=float),
        )

    @property
    def size(self) -> float:
        """The skeleton's extent (m): the diagonal of its rest bounding box."""
        pts = np.vstack((self.head0, self.tail0))
        return float(np.linalg.norm(pts.max(axis=0) - pts.min(axis=0)))


def key_pose(skel: Skeleton, key: Keyframe) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(head (nb,3), tail (nb,3), rotation (nb,4)) of every bone in a key, world frame."""
    head = np.array([key.bones[n].head for n in skel.names], dtype=float)
    rot = np.array([key.bones[n].rotation for n in skel.names], dtype=float)
    tail = head + quat.rotate(rot, skel.tail0 - skel.head0)
    return head, tail, rot
