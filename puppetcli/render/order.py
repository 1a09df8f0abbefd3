"""Painter's algorithm: the order in which to draw a picture's items, far to near.

Items are sorted by the depth of their centre, with one refinement for flat
faces (box faces of props and bones), whose centre depth misleads for large
faces such as a table top with a hand resting on it.  For a face F and another
item O whose pictures' bounding boxes overlap, if O lies entirely on the eye's
side of F's plane, O cannot be hidden by F, so F is drawn first; if O lies
entirely behind the plane, O is drawn first (the plane test of Newell, Newell
and Sancha, 1972).  These constraints are applied by a topological sort that
always takes, among the items whose predecessors are drawn, the one with the
greatest *effective* depth: its own depth or that of anything that must come
after it.  A cycle (interpenetrating shapes) is broken by the deepest item.
"""

from __future__ import annotations

import heapq
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

__all__ = ["Item", "paint_order"]

SIDE_TOLERANCE = 0.005  # m: a shape touching a face (a hand resting on a table) counts as in front


@dataclass(frozen=True)
class Item:
    """One drawable: depth (m, of its centre), group (items of one shape share it), paint,
    screen box (x0, y0, x1, y1) px, world points (k,3) with a radius (m) bounding the shape,
    and for a flat face its plane (unit normal towards the eye, a point on it)."""

    depth: float
    group: int
    paint: Callable[[np.ndarray], None]
    box: np.ndarray
    points: np.ndarray
    radius: float = 0.0
    plane: tuple[np.ndarray, np.ndarray] | None = None


def _side(plane: tuple[np.ndarray, np.ndarray], item: Item) -> int:
    """+1: ``item`` wholly on the eye's side of ``plane``; −1: wholly behind; 0: across."""
    normal, point = plane
    s = (item.points - point) @ normal
    if np.all(s - item.radius > -SIDE_TOLERANCE):
        return 1
    if np.all(s + item.radius < SIDE_TOLERANCE):
        return -1
    return 0


def _overlap(a: Item, b: Item) -> bool:
    return bool(np.all(a.box[:2] <= b.box[2:]) and np.all(b.box[:2] <= a.box[2:]))


def _constraints(items: Sequence[Item]) -> set[tuple[int, int]]:
    """Pairs (i, j): item i must be drawn before item j."""
    edges: set[tuple[int, int]] = set()
    for f, face in enumerate(items):
        if face.plane is None:
            continue
        for o, other in enumerate(items):
            if other.group == face.group or not _overlap(face, other):
                continue
            side = _side(face.plane, other)
            if side > 0 and (o, f) not in edges:
                edges.add((f, o))
            elif side < 0 and (f, o) not in edges:
                edges.add((o, f))
    return edges


def _effective_depth(items: Sequence[Item], edges: set[tuple[int, int]]) -> list[float]:
    """Each item's depth raised to that of anything that must be drawn after it."""
    eff = [item.depth for item in items]
    for _ in range(len(items)):
        changed = False
        for i, j in sorted(edges):
            if eff[j] > eff[i]:
                eff[i], changed = eff[j], True
        if not changed:
            break
    return eff


def paint_order(items: Sequence[Item]) -> list[int]:
    """Indices of ``items`` in drawing order (far to near, plane constraints respected)."""
    edges = _constraints(items)
    eff = _effective_depth(items, edges)
    before = [0] * len(items)
    after: list[list[int]] = [[] for _ in items]
    for i, j in sorted(edges):
        before[j] += 1
        after[i].append(j)

    def key(i: int) -> tuple:
        return (-eff[i], -items[i].depth, items[i].group, i)

    ready = [key(i) for i in range(len(items)) if before[i] == 0]
    heapq.heapify(ready)
    done = [False] * len(items)
    order: list[int] = []
    while len(order) < len(items):
        if not ready:  # a cycle: release its deepest item
            i = min((i for i in range(len(items)) if not done[i]), key=key)
            before[i] = 0
            ready.append(key(i))
        i = heapq.heappop(ready)[-1]
        if done[i]:
            continue
        done[i] = True
        order.append(i)
        for j in after[i]:
            before[j] -= 1
            if before[j] == 0 and not done[j]:
                heapq.heappush(ready, key(j))
    return order
