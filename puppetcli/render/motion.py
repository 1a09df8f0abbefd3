"""Poses of a rig from a file that carries its own skeleton and motion (BVH, glTF).

A file's frames give every joint's world position and rotation; a rig's bone
has world-aligned rest frames.  So the rig's rest pose must be found in the
file first: it is the file's own rest pose (BVH OFFSETs, glTF bind pose) or
one of its frames (``rig from-bvh --frame N``).  Each candidate's joint
positions, scaled to metres (the ratio of the rig's joint-to-joint lengths to
the file's), are compared with the rig's heads, relative to the root; the
first that agrees within ``MATCH`` × the rig's size is the rest pose P.  Then
frame f draws bone b at

    head_b = s · p_f(j) + c,    rotation_b = q_f(j) ⊗ q_P(j)⁻¹,

where j is b's joint (same name) and s the scale.  For a frame P = N,
c = head₀(root) − s · p_N(root) puts frame N exactly where the rig stands, so
frame N of a rig made from frame N is its rest picture.  For the file's rest
pose c = 0: the frames keep the file's own placement (a BVH root's position
channels replace its OFFSET, so the rest pose's root position says nothing
about where the frames are).  When no candidate agrees (a rig made from another file with
the same joint names) the file's rest pose is used, with a warning naming the
bone furthest off.

Standing on the ground.  A rig made from the file's rest pose has its ground
under that pose, but a motion-capture file's frames are placed by its root
channels (hips about 1 m up, the rest pose often at the origin).  So, when P is
the file's rest pose and the rig has a ground, the motion is moved vertically,
once for all frames, so that its lowest point over every frame (bone shapes
included) touches the ground, unless it already lies within ``GROUND_SLACK`` ×
the rig's size of it (our own exports, a doll standing on its ground).  A note
says how far.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from puppetcli.render.camera import RenderError
from puppetcli.render.scene import Pose
from puppetcli.rig.skeleton import Skeleton
from solver import quat
from solver.spec import RigSpec

__all__ = ["MAX_PANELS", "Motion", "motion_poses"]

MAX_PANELS = 48  # frames shown at most (evenly spaced, first and last included)
MATCH = 1e-6  # × rig size: a candidate rest pose agrees with the rig's
GROUND_SLACK = 0.05  # × rig size: a motion this near its ground is left where it is


@dataclass(frozen=True)
class Motion:
    """A file's skeleton and frames, in file units.

    names, parents (nj,); rest_heads (nj,3), rest_rots (nj,4): the file's own rest pose;
    heads (nf,nj,3), rots (nf,nj,4): world joint positions and rotations per frame;
    times (nf,) s; labels (nf,); source: the file's name for messages."""

    names: tuple[str, ...]
    parents: np.ndarray
    rest_heads: np.ndarray
    rest_rots: np.ndarray
    heads: np.ndarray
    rots: np.ndarray
    times: np.ndarray
    labels: tuple[str, ...]
    source: str


def _joint_index(skel: Skeleton, motion: Motion) -> np.ndarray:
    """Index of each rig bone among the file's joints: same name, or the name with runs of
    whitespace and braces replaced by ``_`` (as BVH writers must)."""
    index = {n: i for i, n in enumerate(motion.names)}
    out = []
    for bone in skel.names:
        i = index.get(bone, index.get(re.sub(r"[\s{}]+", "_", bone)))
        if i is None:
            raise RenderError(
                f"{motion.source}: expected a joint for every bone of the rig, got no {bone!r}"
            )
        out.append(i)
    return np.array(out, dtype=np.int64)


def _scale(skel: Skeleton, rest: np.ndarray) -> float:
    """Metres per file unit: the rig's joint-to-joint lengths over the file's (``rest``: the
    file's joint positions in rig bone order)."""
    child = np.flatnonzero(skel.parents >= 0)
    parent = skel.parents[child]
    rig = np.linalg.norm(skel.head0[child] - skel.head0[parent], axis=1).sum()
    file = np.linalg.norm(rest[child] - rest[parent], axis=1).sum()
    return float(rig / file) if file > 0.0 and rig > 0.0 else 1.0


def _rest_candidate(skel: Skeleton, motion: Motion, index: np.ndarray, scale: float):
    """(candidate: −1 for the file's rest pose or a frame index, worst offset (m), its bone)
    of the first pose that matches the rig's rest within ``MATCH``, else of the file's rest."""
    root = int(np.flatnonzero(skel.parents < 0)[0])
    want = skel.head0 - skel.head0[root]
    poses = np.concatenate((motion.rest_heads[None], motion.heads))[:, index] * scale
    off = np.linalg.norm(poses - poses[:, root : root + 1] - want, axis=2)  # (1+nf, nb)
    worst = off.max(axis=1)
    good = np.flatnonzero(worst <= MATCH * max(skel.size, 1e-12))
    k = int(good[0]) if len(good) else 0
    return k - 1, float(worst[k]), skel.names[int(np.argmax(off[k]))]


def _lowest(skel: Skeleton, head: np.ndarray, tail: np.ndarray) -> float:
    """The lowest point (y) of every bone shape over all frames (a box by its bounding
    sphere)."""
    kind = np.array(skel.shape)
    reach = np.where(kind == "box", np.linalg.norm(skel.half, axis=1), skel.radius)
    low = np.where(
        kind == "capsule",
        np.minimum(head[..., 1], tail[..., 1]),
        0.5 * (head[..., 1] + tail[..., 1]),
    )
    return float((low - reach).min())


def motion_poses(
    motion: Motion,
    skel: Skeleton,
    spec: RigSpec,
    frames: Sequence[int] = (),
    say: Callable[[str], None] = lambda line: None,
) -> list[Pose]:
    """The poses of ``frames`` (default: at most ``MAX_PANELS``, evenly spaced) as the rig's
    (see the module docstring); notes and warnings go to ``say``."""
    nf = len(motion.times)
    if nf < 1:
        raise RenderError(f"{motion.source}: expected at least one frame, got none")
    for f in frames:
        if not 0 <= f < nf:
            raise RenderError(
                f"{motion.source}: --frame: expected a frame from 0 to {nf - 1}, got {f}"
            )
    index = _joint_index(skel, motion)
    scale = _scale(skel, motion.rest_heads[index])
    candidate, worst, bone = _rest_candidate(skel, motion, index, scale)
    if worst > MATCH * max(skel.size, 1e-12):
        say(
            f"warning: {motion.source}: the rig's rest pose is neither the file's rest pose nor "
            f"one of its frames (bone {bone!r} {worst:.3g} m off): drawn from the file's rest pose"
        )
    p_rest = motion.rest_heads if candidate < 0 else motion.heads[candidate]
    q_rest = motion.rest_rots if candidate < 0 else motion.rots[candidate]
    root = int(np.flatnonzero(skel.parents < 0)[0])
    shift = skel.head0[root] - scale * p_rest[index[root]] if candidate >= 0 else 0.0
    rot = quat.normalize(quat.mul(motion.rots[:, index], quat.conj(q_rest[index])))
    head = scale * motion.heads[:, index] + shift
    tail = head + quat.rotate(rot, np.broadcast_to(skel.tail0 - skel.head0, head.shape))
    if candidate < 0 and spec.ground is not None:
        gap = _lowest(skel, head, tail) - spec.ground.height
        if abs(gap) > GROUND_SLACK * skel.size:
            head[..., 1] -= gap
            tail[..., 1] -= gap
            way = "lowered" if gap > 0 else "raised"
            say(f"note: {motion.source}: motion {way} {abs(gap):.3g} m to stand on the ground")
    picks = list(frames) or np.unique(np.linspace(0, nf - 1, min(MAX_PANELS, nf)).round())
    return [
        Pose(head[f], tail[f], rot[f], motion.labels[f], float(motion.times[f]))
        for f in (int(f) for f in picks)
    ]
