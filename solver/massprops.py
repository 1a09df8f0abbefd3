"""Mass properties of bone and prop shapes.

A shape's local frame has its y axis along the bone (head → tail) for capsules
and boxes, origin at the shape centre.  Capsule: a cylinder of length L and
radius r with two hemispherical caps; its inertia about its centre is the sum of
the cylinder's and the caps' (parallel-axis theorem for the caps, whose own
centroid sits 3r/8 from the flat face).
"""

from __future__ import annotations

import numpy as np

from solver import quat
from solver.spec import ShapeSpec


def shape_volume(shape: ShapeSpec, length: float) -> float:
    """Volume (m³) of a shape spanning a bone of ``length`` (m)."""
    r = shape.radius
    if shape.kind == "sphere":
        return 4.0 / 3.0 * np.pi * r**3
    if shape.kind == "capsule":
        return np.pi * r * r * length + 4.0 / 3.0 * np.pi * r**3
    hx, hy, hz = shape.half_extents
    return 8.0 * hx * hy * hz


def shape_inertia_local(shape: ShapeSpec, length: float, mass: float) -> np.ndarray:
    """Inertia tensor (3, 3) in kg·m² about the shape centre, in the shape's local frame."""
    r = shape.radius
    if shape.kind == "sphere":
        return np.eye(3) * (0.4 * mass * r * r)
    if shape.kind == "box":
        sx, sy, sz = (2.0 * h for h in shape.half_extents)
        return np.diag([sy * sy + sz * sz, sx * sx + sz * sz, sx * sx + sy * sy]) * (mass / 12.0)
    cyl = np.pi * r * r * length
    caps = 4.0 / 3.0 * np.pi * r**3
    m_cyl = mass * cyl / (cyl + caps)
    m_caps = mass - m_cyl
    axial = 0.5 * m_cyl * r * r + 0.4 * m_caps * r * r
    perp = m_cyl * (length * length / 12.0 + r * r / 4.0) + m_caps * (
        0.4 * r * r + length * length / 4.0 + 3.0 * length * r / 8.0
    )
    return np.diag([perp, axial, perp])


def shape_frame(head: np.ndarray, tail: np.ndarray) -> np.ndarray:
    """Rest orientation (w,x,y,z) of a bone shape's local frame: local y along head → tail.

    A zero-length bone keeps the world axes.
    """
    axis = tail - head
    if np.linalg.norm(axis) < 1e-12:
        return quat.IDENTITY.copy()
    return quat.from_two_vectors(np.array([0.0, 1.0, 0.0]), axis)


def world_inertia(shape: ShapeSpec, head: np.ndarray, tail: np.ndarray, mass: float) -> np.ndarray:
    """Rest-pose inertia (3, 3) about the shape centre in world-aligned axes."""
    length = float(np.linalg.norm(tail - head))
    rot = quat.matrix(shape_frame(head, tail))
    return rot @ shape_inertia_local(shape, length, mass) @ rot.T
