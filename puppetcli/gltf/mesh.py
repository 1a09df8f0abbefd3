"""Triangle meshes of bone shapes, for files that show the doll in any viewer.

A capsule is every point within ``radius`` of its segment head → tail: a
cylinder of ``SEGMENTS`` sides closed by two hemispheres of ``RINGS`` rings,
each with a pole vertex on the axis.  Every vertex lies on the surface (at
exactly ``radius`` from the segment, up to rounding), so a reader can recover
the capsule from its vertices (``puppetcli.gltf.rig``).  A sphere is a capsule
of zero length at the bone's midpoint; a box has 24 vertices (4 per face, so
each face has its own normal).  Normals are unit outward normals; triangles
wind counter-clockwise seen from outside (glTF's front faces).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from puppetcli.rig.skeleton import Skeleton
from solver import quat
from solver.massprops import shape_frame

__all__ = ["RINGS", "SEGMENTS", "TriangleMesh", "bone_mesh", "skeleton_mesh"]

SEGMENTS = 16  # sides of a capsule around its axis
RINGS = 4  # latitude rings of each hemisphere, pole excluded
_Y = np.array([0.0, 1.0, 0.0])
_BOX_FACES = (  # (normal axis, sign) of each face
    (0, 1.0), (0, -1.0), (1, 1.0), (1, -1.0), (2, 1.0), (2, -1.0),
)  # fmt: skip


@dataclass(frozen=True)
class TriangleMesh:
    """positions, normals (n,3) m; triangles (m,3) vertex indices; bone (n,) the bone of
    every vertex."""

    positions: np.ndarray
    normals: np.ndarray
    triangles: np.ndarray
    bone: np.ndarray


def _capsule_local(length: float, radius: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(positions, normals, triangles) of a capsule along +y from 0 to ``length``."""
    around = 2.0 * np.pi * np.arange(SEGMENTS) / SEGMENTS
    ring = np.stack((np.cos(around), np.zeros(SEGMENTS), -np.sin(around)), axis=1)
    # Rings from the bottom pole up to the bottom equator (at y = 0), then from the top
    # equator (at y = length) up to the top pole.
    lat = np.pi / 2.0 * np.arange(RINGS + 1) / RINGS
    lows = [(-np.cos(a), np.sin(a), 0.0) for a in lat[1:]]
    highs = [(np.sin(a), np.cos(a), length) for a in lat[:-1]]
    rows = lows + (highs if length > 0.0 else highs[1:])  # a sphere has one equator
    normals = [np.array([[0.0, -1.0, 0.0]])]
    centres = [np.zeros((1, 3))]
    for ny, s, y in rows:
        normals.append(ring * s + np.array([0.0, ny, 0.0]))
        centres.append(np.tile([0.0, y, 0.0], (SEGMENTS, 1)))
    normals.append(np.array([[0.0, 1.0, 0.0]]))
    centres.append(np.array([[0.0, length, 0.0]]))
    normal = np.vstack(normals)
    position = np.vstack(centres) + radius * normal
    return position, normal, _capsule_triangles(len(rows))


def _capsule_triangles(nrows: int) -> np.ndarray:
    """Triangles of a pole, ``nrows`` rings of ``SEGMENTS`` vertices, a pole."""
    tris = []
    k = np.arange(SEGMENTS)
    nxt = (k + 1) % SEGMENTS
    first, top = 1, 1 + nrows * SEGMENTS
    tris += [(0, first + nxt[i], first + k[i]) for i in range(SEGMENTS)]
    for r in range(nrows - 1):
        a, b = first + r * SEGMENTS, first + (r + 1) * SEGMENTS
        for i in range(SEGMENTS):
            tris += [(a + k[i], a + nxt[i], b + nxt[i]), (a + k[i], b + nxt[i], b + k[i])]
    last = first + (nrows - 1) * SEGMENTS
    tris += [(top, last + k[i], last + nxt[i]) for i in range(SEGMENTS)]
    return np.array(tris, dtype=np.int64)


def _box_local(half: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(positions, normals, triangles) of a box centred at 0 with half sizes ``half``."""
    positions, normals, tris = [], [], []
    for axis, sign in _BOX_FACES:
        u, v = (axis + 1) % 3, (axis + 2) % 3
        corners = []
        for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
            p = np.zeros(3)
            p[axis], p[u], p[v] = sign * half[axis], a * half[u], sign * b * half[v]
            corners.append(p)
        n = np.zeros(3)
        n[axis] = sign
        base = len(positions)
        positions += corners
        normals += [n] * 4
        tris += [(base, base + 1, base + 2), (base, base + 2, base + 3)]
    return np.array(positions), np.array(normals), np.array(tris, dtype=np.int64)


def bone_mesh(
    kind: str, head: np.ndarray, tail: np.ndarray, radius: float, half: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(positions, normals, triangles) of one bone shape at rest, world frame."""
    head, tail = np.asarray(head, float), np.asarray(tail, float)
    if kind == "box":
        pos, nrm, tris = _box_local(np.asarray(half, float))
        centre = 0.5 * (head + tail)
    else:
        length = float(np.linalg.norm(tail - head)) if kind == "capsule" else 0.0
        pos, nrm, tris = _capsule_local(length, radius)
        centre = head if kind == "capsule" else 0.5 * (head + tail)
    q = shape_frame(head, tail) if kind != "sphere" else quat.IDENTITY
    rot = np.broadcast_to(q, (len(pos), 4))
    return centre + quat.rotate(rot, pos), quat.rotate(rot, nrm), tris


def skeleton_mesh(skel: Skeleton) -> TriangleMesh:
    """Every bone's rest shape in one mesh, each vertex tagged with its bone."""
    positions, normals, tris, bone = [], [], [], []
    count = 0
    for i, kind in enumerate(skel.shape):
        pos, nrm, t = bone_mesh(kind, skel.head0[i], skel.tail0[i], skel.radius[i], skel.half[i])
        positions.append(pos)
        normals.append(nrm)
        tris.append(t + count)
        bone.append(np.full(len(pos), i))
        count += len(pos)
    return TriangleMesh(np.vstack(positions), np.vstack(normals), np.vstack(tris),
                        np.concatenate(bone))  # fmt: skip
