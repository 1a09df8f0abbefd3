"""A rig (YAML text, docs/rig-format.md) from a BVH skeleton.

Every BVH joint becomes a bone of the same name, hanging from its parent's bone
at its head, in the file's depth-first order.

Rest pose.  The skeleton given by the OFFSETs (all channels 0, the root at its
OFFSET), or the skeleton posed by frame N (its channels through the forward
kinematics of ``puppetcli.bvh.model``); either way the rig's rest pose *is* that
skeleton, with world-aligned rest frames.  Positions are multiplied by
``scale`` (file units → metres; ``puppetcli.bvh.units`` infers it).

Tails.  A leaf's tail is its End Site (the mean of several; its head when it
has none).  A joint with one child has its tail at the child's head; with
several, at the mean of their heads, unless that mean lies within half of
their mean distance of the head (children on opposite sides, e.g. hips with
two legs and a spine), then at the first child's head away from the head.

Shapes, masses and joints are ``puppetcli.rig.make``'s.
"""

from __future__ import annotations

import numpy as np

from puppetcli.bvh.model import Bvh, BvhError
from puppetcli.rig.make import BoneGeometry, bone_geometry, children_tail, rig_text

__all__ = ["check_frame", "rig_text_from_bvh", "skeleton_points"]


def skeleton_points(bvh: Bvh, frame: int | None) -> tuple[np.ndarray, list[np.ndarray]]:
    """(joint positions (nj,3), End Site positions per joint) in file units."""
    heads, world = bvh.forward_kinematics(frame)
    return heads, bvh.end_sites(heads, world)


def rig_text_from_bvh(
    bvh: Bvh, name: str, scale: float, frame: int | None = None, note: str = ""
) -> str:
    """Rig YAML for ``bvh`` (see the module docstring), checked by the rig loader."""
    check_frame(bvh, frame)
    return rig_text(name, _bones(bvh, frame, scale), note, bvh.source)


def check_frame(bvh: Bvh, frame: int | None) -> None:
    """A ``--frame`` must name a frame of the file."""
    if frame is None or 0 <= frame < bvh.nframes:
        return
    got = f"{frame} (Frames: {bvh.nframes})"
    raise BvhError(
        f"{bvh.source}: --frame: expected a frame index from 0 to {bvh.nframes - 1}, got {got}"
        if bvh.nframes
        else f"{bvh.source}: --frame: expected a file with frames, got Frames: 0"
    )


def _bones(bvh: Bvh, frame: int | None, scale: float) -> BoneGeometry:
    heads, ends = skeleton_points(bvh, frame)
    heads = heads * scale
    ends = [e * scale for e in ends]
    parents = bvh.parents
    tails = np.array([_tail(i, heads, ends, parents) for i in range(len(heads))])
    return bone_geometry(bvh.names, parents, heads, tails)


def _tail(i: int, heads: np.ndarray, ends: list[np.ndarray], parents: np.ndarray) -> np.ndarray:
    """The bone's tail: End Sites, one child's head, or the children's mean (see above)."""
    tail = children_tail(i, heads, parents)
    if tail is not None:
        return tail
    return ends[i].mean(axis=0) if len(ends[i]) else heads[i]
