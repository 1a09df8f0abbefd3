"""Collision detection: candidate pairs (broad phase) and contacts (narrow phase).

Shapes
------
A shape sits in its body's frame (static shapes, body −1, in the world).  With
body pose (x_B, q_B) its world centre and orientation are

    c = x_B + R(q_B)·shape_pos,    q = q_B ⊗ shape_quat,

and y = R(q)·ŷ is its axis.  Kinds: 0 plane through c with normal y, solid below
(always static); 1 sphere of radius r about c; 2 capsule, the points within r of
the segment c ± l·y (l = shape_half[1]); 3 box |R(q)ᵀ(x − c)|_i ≤ h_i.  A sphere
is a capsule with l = 0 and shares its kernels.

Contacts
--------
A contact of pair (a, b) has a world point p, a unit normal n and a depth d:

* n points from a to b: moving b by +ε·n separates the shapes (to first order);
* d > 0 is overlap along n, d < 0 a gap; only d ≥ −margin is reported
  (speculative contacts, so the solver can stop a gap closing within one step);
* p is midway between the two surface points: p = x_b + n·d/2, x_b the point of
  b's surface deepest along −n;
* key = pair·16 + feature, the feature (< 16) naming the corner, segment end…
  that produced it, so the same contact keeps its key from step to step and warm
  starts can find last step's impulse.  Contacts are sorted by key.
* friction = sqrt(μ_a·μ_b).

Features: plane–sphere 0; plane–capsule 0, 1 (ends); plane–box 0–7 (corners);
sphere/capsule–sphere/capsule 0 (closest points, when not also an overlap end),
1, 2 (ends of b's overlap with a's axis; a sphere pair uses 1 alone);
sphere/capsule–box 0 (deepest point, when not an end), 1, 2 (segment ends; a
sphere uses 1 alone); box–box 0–15 (see ``collide_boxbox``).

The narrow phase orders each pair by kind class (plane < sphere = capsule < box),
so a box–capsule pair is computed as capsule–box with its normal negated.  A
bounding-sphere test (radius r, r + l or |h|; a plane tests the signed distance of
the centre) drops pairs farther apart than the margin first.  The kernels live in
``collide_segment`` (plane/segment pairs), ``collide_box`` (box against plane and
segment) and ``collide_boxbox``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from solver import quat
from solver.collide.box import plane_box, segment_box
from solver.collide.boxbox import box_box
from solver.collide.segment import Found, plane_segment, segment_segment

PLANE, SPHERE, CAPSULE, BOX = 0, 1, 2, 3
FEATURES = 16
"""Contact keys are pair·FEATURES + feature."""
REST_OVERLAP = 1e-9
"""m: a rest-pose depth above this counts as overlapping for ``candidate_pairs``."""
_CLASS = np.array([0, 1, 1, 2])  # kind → class: plane, segment (sphere/capsule), box


@dataclass(frozen=True)
class Geometry:
    """Collision shapes and the candidate pairs among them.

    shape_body: (ns,) int64 body index, −1 = static (world) shape.
    shape_kind: (ns,) int64: 0 plane, 1 sphere, 2 capsule, 3 box.
    shape_pos: (ns,3) shape centre in its body's frame (static: world), m.
    shape_quat: (ns,4) orientation in its body's frame (static: world), (w,x,y,z);
        the capsule axis and the plane normal are the local +y.
    shape_radius: (ns,) sphere/capsule radius, m.
    shape_half: (ns,3) box half extents; capsule [0, half segment length, 0]; else 0 (m).
    shape_friction: (ns,) Coulomb coefficient.
    pair_a, pair_b: (np,) int64 candidate pairs, indices into the shapes.
    """

    shape_body: np.ndarray
    shape_kind: np.ndarray
    shape_pos: np.ndarray
    shape_quat: np.ndarray
    shape_radius: np.ndarray
    shape_half: np.ndarray
    shape_friction: np.ndarray
    pair_a: np.ndarray
    pair_b: np.ndarray


@dataclass(frozen=True)
class Contacts:
    """Contacts of one configuration, sorted by key.

    body_a, body_b: (nc,) int64 bodies, −1 = static.
    point: (nc,3) world point midway between the surfaces, m.
    normal: (nc,3) unit, from a towards b.
    depth: (nc,) penetration, m (> 0 overlap, < 0 gap down to −margin).
    friction: (nc,) combined Coulomb coefficient sqrt(μ_a·μ_b).
    key: (nc,) int64 pair index·16 + feature index, stable while the feature persists.
    """

    body_a: np.ndarray
    body_b: np.ndarray
    point: np.ndarray
    normal: np.ndarray
    depth: np.ndarray
    friction: np.ndarray
    key: np.ndarray


def candidate_pairs(
    shape_body: np.ndarray,
    shape_kind: np.ndarray,
    shape_pos: np.ndarray,
    shape_quat: np.ndarray,
    shape_radius: np.ndarray,
    shape_half: np.ndarray,
    body_parent: np.ndarray,
    body_pos: np.ndarray,
    body_quat: np.ndarray,
    exclude_rest_overlap: bool = True,
    body_movable: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Shape pairs (pair_a, pair_b) that may ever touch, sorted by (a, b).

    Excluded: two static shapes, two shapes that cannot move (static or of immovable
    bodies, body_movable (nb,) bool; a fixed root on the ground has no contact to solve:
    its rows would have no response), two shapes of one body, shapes of a parent and
    its child (body_parent (nb,), −1 for roots), and — with ``exclude_rest_overlap``
    — two body shapes already overlapping (depth > REST_OVERLAP) in the pose
    body_pos (nb,3), body_quat (nb,4), as rig capsules do around a joint.  A body
    overlapping a static shape (a foot sunk in the ground) keeps its pair: dropping
    it would let the body fall through.  A static shape is always ``a``.
    """
    i, j = np.triu_indices(len(shape_body), k=1)
    bi, bj = shape_body[i], shape_body[j]
    parent = np.append(np.asarray(body_parent, dtype=np.int64), -2)  # index −1 → no parent
    linked = (bi >= 0) & (bj >= 0) & ((parent[bi] == bj) | (parent[bj] == bi))
    moves = np.append(np.ones(len(parent) - 1, bool) if body_movable is None else body_movable,
                      False)  # fmt: skip
    keep = (moves[bi] | moves[bj]) & (bi != bj) & ~linked
    i, j, static_j = i[keep], j[keep], bj[keep] < 0
    a, b = np.where(static_j, j, i), np.where(static_j, i, j)
    order = np.lexsort((b, a))
    a, b = a[order].astype(np.int64), b[order].astype(np.int64)
    if not exclude_rest_overlap or len(a) == 0:
        return a, b
    geom = Geometry(
        shape_body, shape_kind, shape_pos, shape_quat, shape_radius, shape_half,
        shape_friction=np.ones(len(shape_body)), pair_a=a, pair_b=b,
    )  # fmt: skip
    rest = collide(geom, body_pos, body_quat, margin=0.0)
    overlap = np.zeros(len(a), dtype=bool)
    overlap[rest.key[rest.depth > REST_OVERLAP] // FEATURES] = True
    overlap &= shape_body[a] >= 0
    return a[~overlap], b[~overlap]


def world_shapes(
    geom: Geometry, body_pos: np.ndarray, body_quat: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """World centres (ns,3) and rotation matrices (ns,3,3) of all shapes."""
    body = geom.shape_body
    moving = np.flatnonzero(body >= 0)
    centre = geom.shape_pos.astype(float)
    q = geom.shape_quat.astype(float)
    if len(moving):
        bq = body_quat[body[moving]]
        centre[moving] = body_pos[body[moving]] + quat.rotate(bq, geom.shape_pos[moving])
        q[moving] = quat.mul(bq, geom.shape_quat[moving])
    return centre, quat.matrix(q)


def shape_bounds(geom: Geometry) -> np.ndarray:
    """(ns,) m: radius of each shape's bounding sphere about its centre."""
    return np.where(
        geom.shape_kind == BOX,
        np.linalg.norm(geom.shape_half, axis=1),
        geom.shape_radius + geom.shape_half[:, 1],
    )


def _near(
    geom: Geometry, centre: np.ndarray, rot: np.ndarray, f: np.ndarray, s: np.ndarray, margin: float
) -> np.ndarray:
    """Bounding-sphere test (np,) bool: can first f and second s be within margin?"""
    kind = geom.shape_kind
    bound = shape_bounds(geom)
    offset = centre[s] - centre[f]
    gap = np.where(
        kind[f] == PLANE,
        np.einsum("ki,ki->k", offset, rot[f, :, 1]),
        np.linalg.norm(offset, axis=1) - bound[f],
    )
    return gap - bound[s] <= margin


def _segments(geom: Geometry, centre: np.ndarray, rot: np.ndarray, s: np.ndarray):
    """Segment arguments (centre, unit axis, half length, radius) of spheres/capsules s."""
    return centre[s], rot[s, :, 1], geom.shape_half[s, 1], geom.shape_radius[s]


def _boxes(geom: Geometry, centre: np.ndarray, rot: np.ndarray, s: np.ndarray):
    """Box arguments (centre, rotation, half extents) of boxes s."""
    return centre[s], rot[s], geom.shape_half[s]


def _run(
    group: tuple[int, int],
    geom: Geometry,
    centre: np.ndarray,
    rot: np.ndarray,
    f: np.ndarray,
    s: np.ndarray,
    margin: float,
) -> Found:
    """Narrow phase of one kind-class group; normals point from f to s."""
    if group == (0, 1):
        return plane_segment(centre[f], rot[f, :, 1], *_segments(geom, centre, rot, s), margin)
    if group == (0, 2):
        return plane_box(centre[f], rot[f, :, 1], *_boxes(geom, centre, rot, s), margin)
    if group == (1, 1):
        seg_f, seg_s = _segments(geom, centre, rot, f), _segments(geom, centre, rot, s)
        return segment_segment(*seg_f, *seg_s, margin)
    if group == (1, 2):
        point, normal, depth, keep = segment_box(
            *_boxes(geom, centre, rot, s), *_segments(geom, centre, rot, f), margin
        )
        return point, -normal, depth, keep
    return box_box(*_boxes(geom, centre, rot, f), *_boxes(geom, centre, rot, s), margin)


_GROUPS = ((0, 1), (0, 2), (1, 1), (1, 2), (2, 2))


def collide(
    geom: Geometry,
    body_pos: np.ndarray,
    body_quat: np.ndarray,
    margin: float,
    cull: bool = True,
    active: np.ndarray | None = None,
) -> Contacts:
    """Contacts (depth ≥ −margin, m) of the candidate pairs of geom in the pose
    body_pos (nb,3), body_quat (nb,4); see the module docstring for conventions.
    ``cull``: skip the narrow phase of pairs whose bounding spheres are apart by more
    than the margin (it would find nothing there); ``active`` (npair,) bool: only these
    pairs (the others' bodies sleep: solver.advance.sleep)."""
    a, b = geom.pair_a, geom.pair_b
    cls = _CLASS[geom.shape_kind]
    swap = cls[a] > cls[b]
    f, s = np.where(swap, b, a), np.where(swap, a, b)
    centre, rot = world_shapes(geom, body_pos, body_quat)
    near = _near(geom, centre, rot, f, s, margin) if cull else np.ones(len(f), dtype=bool)
    if active is not None:
        near &= active
    parts = []
    for group in _GROUPS:
        sel = np.flatnonzero(near & (cls[f] == group[0]) & (cls[s] == group[1]))
        if len(sel):
            point, normal, depth, keep = _run(group, geom, centre, rot, f[sel], s[sel], margin)
            rows, feature = np.nonzero(keep)
            pair = sel[rows]
            sign = np.where(swap[pair], -1.0, 1.0)[:, None]  # normals a → b again
            at = (rows, feature)
            parts.append((pair, feature, point[at], sign * normal[at], depth[at]))
    return _assemble(geom, parts)


def _assemble(geom: Geometry, parts: list) -> Contacts:
    """Concatenate per-group contacts and sort them by key."""
    if not parts:
        empty = np.zeros(0, dtype=np.int64)
        return Contacts(
            empty, empty, np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), np.zeros(0), empty
        )
    pair, feature, point, normal, depth = (np.concatenate(p) for p in zip(*parts, strict=True))
    key = pair * FEATURES + feature
    order = np.argsort(key, kind="stable")
    pair = pair[order]
    a, b = geom.pair_a[pair], geom.pair_b[pair]
    mu = geom.shape_friction
    return Contacts(
        body_a=geom.shape_body[a].astype(np.int64),
        body_b=geom.shape_body[b].astype(np.int64),
        point=point[order],
        normal=normal[order],
        depth=depth[order],
        friction=np.sqrt(mu[a] * mu[b]),
        key=key[order].astype(np.int64),
    )
