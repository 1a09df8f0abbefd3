"""A rig (YAML text, docs/rig-format.md) from a skinned glTF character.

Bones are the skin's joints, parents first (``puppetcli.gltf.read.skin_joints``),
named as the joint nodes; the rest pose is the bind pose: a bone's head is its
joint's bind position (glTF is in metres).

Shapes from the mesh.  Every vertex of the meshes bound to the skin belongs to
the joint with its largest weight.  A bone whose vertices form a capsule
starting at its head (every vertex at the same distance r from the segment
head → tail, tail found from the vertex furthest from the head, up to
``CAPSULE_MATCH``: a puppetcli export) gets that capsule exactly.  Otherwise its
tail is the children's (``rig from-bvh``'s rule), or for a leaf, along the
vertices' main axis (their covariance's largest eigenvector, pointing from the
head towards them) to the furthest of them less the radius; its radius is the
90th percentile of its vertices' distances from the segment head → tail.  A bone without
vertices falls back on ``rig from-bvh``'s radius (a fraction of its length);
a leaf without vertices is a small sphere.  Masses, joints and the ground are
``puppetcli.rig.make``'s.

The rig records the file and skin (``character:``), so the keys it takes can
be written as an animation of the character itself (``puppetcli.gltf.character``).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from puppetcli.gltf.read import Gltf, SkinJoints, skin_joints
from puppetcli.rig.make import bone_geometry, children_tail, rig_text

__all__ = ["bone_vertices", "rig_text_from_gltf"]

CAPSULE_MATCH = 1e-4  # × (length + radius): vertices this near one distance make a capsule
SNAP = 1e-6  # × skeleton size: a tail this near a child's head is put on it (float32 noise)
RADIUS_PERCENTILE = 90.0
MIN_VERTICES = 4  # a bone with fewer vertices is shaped from its length


def bone_vertices(g: Gltf, skin: int, joints: SkinJoints) -> list[np.ndarray]:
    """Bind-pose positions (n,3) of the vertices bound mostly to each joint, in joint order."""
    per_joint: list[list[np.ndarray]] = [[] for _ in joints.names]
    order = {int(s): k for k, s in enumerate(joints.skin_index)}
    for node in g.doc.nodes:
        if node.skin != skin or node.mesh is None:
            continue
        for prim in g.doc.meshes[node.mesh].primitives:
            a = prim.attributes
            if a.POSITION is None or a.JOINTS_0 is None or a.WEIGHTS_0 is None:
                continue
            pos, ids, weights = (g.accessor(i) for i in (a.POSITION, a.JOINTS_0, a.WEIGHTS_0))
            if (
                pos.shape[1] != 3
                or ids.shape[1] != 4
                or weights.shape[1] != 4
                or not (len(pos) == len(ids) == len(weights))
            ):
                raise g.fail(f"meshes[{node.mesh}]", "POSITION, JOINTS_0 and WEIGHTS_0 of one "
                             "length (VEC3, VEC4, VEC4)", "other shapes")  # fmt: skip
            ids = ids.astype(np.int64)
            top = ids[np.arange(len(ids)), np.argmax(weights, axis=1)]
            for s, k in order.items():
                per_joint[k].append(pos[top == s])
    return [np.vstack(v) if v else np.zeros((0, 3)) for v in per_joint]


def _segment_distance(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    d = b - a
    span = float(d @ d)
    u = np.clip((points - a) @ d / span, 0.0, 1.0) if span > 0.0 else np.zeros(len(points))
    return np.linalg.norm(points - (a + u[:, None] * d), axis=1)


def _exact_capsule(head: np.ndarray, pts: np.ndarray) -> tuple[np.ndarray, float] | None:
    """(tail, radius) when ``pts`` lie on a capsule that starts at ``head``."""
    reach = np.linalg.norm(pts - head, axis=1)
    far, r = float(reach.max()), float(reach.min())
    if far <= r:
        return None
    tail = head + (pts[int(np.argmax(reach))] - head) * ((far - r) / far)
    off = np.abs(_segment_distance(pts, head, tail) - r)
    return (tail, r) if off.max() <= CAPSULE_MATCH * far else None


def _shape(
    k: int, heads: np.ndarray, parents: np.ndarray, pts: np.ndarray
) -> tuple[np.ndarray, float | None]:
    """(tail, radius or None for the default) of bone ``k``."""
    head = heads[k]
    if len(pts) >= MIN_VERTICES:
        exact = _exact_capsule(head, pts)
        if exact is not None:
            return exact
    tail = children_tail(k, heads, parents)
    if len(pts) < MIN_VERTICES:
        return (head if tail is None else tail), None
    if tail is None:  # a leaf: along its vertices' main axis, to where they end
        axis = np.linalg.eigh(np.cov((pts - head).T))[1][:, -1]
        axis = axis if float(np.mean(pts - head, axis=0) @ axis) >= 0.0 else -axis
        length = float(np.max((pts - head) @ axis, initial=0.0))
        r = float(np.percentile(_segment_distance(pts, head, head + length * axis),
                                RADIUS_PERCENTILE))  # fmt: skip
        return head + max(length - r, 0.0) * axis, r
    return tail, float(np.percentile(_segment_distance(pts, head, tail), RADIUS_PERCENTILE))


def _snapped(tails: np.ndarray, heads: np.ndarray, parents: np.ndarray) -> np.ndarray:
    """Tails within ``SNAP`` of a child's head moved onto it."""
    size = float(np.ptp(np.vstack((heads, tails)), axis=0).max())
    out = tails.copy()
    for k in range(len(tails)):
        children = np.flatnonzero(parents == k)
        if len(children):
            off = np.linalg.norm(heads[children] - tails[k], axis=1)
            if off.min() <= SNAP * size:
                out[k] = heads[children[int(np.argmin(off))]]
    return out


def rig_text_from_gltf(g: Gltf, skin: int, name: str, note: str, character: str) -> str:
    """Rig YAML for skin ``skin`` of ``g`` (see the module docstring); ``character`` is the
    file as the rig should name it (relative to the rig's folder)."""
    joints = skin_joints(g, skin)
    heads = joints.bind[:, :3, 3].copy()
    vertices = bone_vertices(g, skin, joints)
    tails, radii = [], []
    for k in range(len(joints.names)):
        tail, radius = _shape(k, heads, joints.parents, vertices[k])
        tails.append(tail)
        radii.append(np.nan if radius is None else radius)
    tail = _snapped(np.array(tails), heads, joints.parents)
    radius = np.array(radii)
    default = bone_geometry(joints.names, joints.parents, heads, tail).radius
    radius = np.where(np.isnan(radius), default, radius)
    bones = bone_geometry(joints.names, joints.parents, heads, tail, radius)
    source = f"character: {{gltf: {json.dumps(character, ensure_ascii=False)}, skin: {skin}}}"
    return rig_text(name, bones, note, Path(g.source).name, (source,))
