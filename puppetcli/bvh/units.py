"""The length unit of a BVH file, inferred: BVH files do not say what their numbers mean.

The figure's size is the largest side of the bounding box of its rest pose
(the OFFSETs, End Sites included): a standing figure's height, or its arm span
in a T-pose, about the same for a human.  Then, in order:

1. The file's own hint: CMU's skeleton (joints ``LHipJoint``, ``RHipJoint`` and
   ``LowerBack``) is in CMU units, inches / 0.45 (0.0564 m).
2. The first unit of ``UNITS`` whose range the size falls in: metres for 0.25–3
   units, feet for 3–8, centimetres for 25–300, millimetres for 300–3,000
   (figures from a small doll to a giant).
3. Otherwise the unit that makes the figure nearest to 1.7 m (in ratio).

The result is a :class:`Unit`; its ``warning`` is set when the figure comes out
outside a human's range (1.0–2.3 m), with the ``--scale`` that would make it
1.7 m tall.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from puppetcli.bvh.model import Bvh

__all__ = ["HUMAN_RANGE", "UNITS", "Unit", "figure_size", "infer_unit"]

CMU = ("CMU units (inches / 0.45)", 0.0254 / 0.45)
CMU_JOINTS = {"LHipJoint", "RHipJoint", "LowerBack"}
# (name, metres per unit, sizes in file units taken to be in this unit)
UNITS = (
    ("metres", 1.0, (0.25, 3.0)),
    ("feet", 0.3048, (3.0, 8.0)),
    ("centimetres", 0.01, (25.0, 300.0)),
    ("millimetres", 0.001, (300.0, 3000.0)),
    ("inches", 0.0254, (math.inf, math.inf)),  # only ever the nearest guess
)
HUMAN_RANGE = (1.0, 2.3)  # m
HUMAN_SIZE = 1.7  # m


@dataclass(frozen=True)
class Unit:
    """name ("centimetres"…), scale (m per file unit), size (file units), why (the rule
    that chose it), warning ("" when the figure is of human size)."""

    name: str
    scale: float
    size: float
    why: str
    warning: str = ""

    def note(self) -> str:
        """One line for stderr: what was assumed and why."""
        return (
            f"skeleton {self.size:.4g} file units across: assuming {self.name} "
            f"({self.why}; --scale {self.scale:.6g})"
        )


def figure_size(bvh: Bvh) -> float:
    """The largest side of the rest pose's bounding box (file units), End Sites included."""
    heads, world = bvh.forward_kinematics(None)
    pts = np.vstack([heads, *bvh.end_sites(heads, world)])
    return float((pts.max(axis=0) - pts.min(axis=0)).max())


def infer_unit(bvh: Bvh) -> Unit:
    """The file's unit (see the module docstring)."""
    size = figure_size(bvh)
    if size <= 0.0:
        return Unit("metres", 1.0, size, "a skeleton of no size")
    if set(bvh.names) >= CMU_JOINTS and _in_human_range(size * CMU[1]):
        return _checked(Unit(CMU[0], CMU[1], size, "CMU's joint names"))
    for name, scale, (low, high) in UNITS:
        if low <= size < high:
            return _checked(Unit(name, scale, size, f"{low:g}–{high:g} units across"))
    name, scale, _ = min(UNITS, key=lambda u: abs(math.log(size * u[1] / HUMAN_SIZE)))
    return _checked(Unit(name, scale, size, f"the unit nearest a {HUMAN_SIZE:g} m figure"))


def _in_human_range(metres: float) -> bool:
    return HUMAN_RANGE[0] <= metres <= HUMAN_RANGE[1]


def _checked(unit: Unit) -> Unit:
    """``unit`` with a warning when the figure is not of human size."""
    metres = unit.size * unit.scale
    if _in_human_range(metres) or unit.size <= 0.0:
        return unit
    human = HUMAN_SIZE / unit.size
    warning = (
        f"the figure is {metres:.3g} m across in {unit.name}, outside a human's "
        f"{HUMAN_RANGE[0]:g}–{HUMAN_RANGE[1]:g} m; if it is a person, pass --scale {human:.3g} "
        f"(makes it {HUMAN_SIZE:g} m), or the scale of the file's unit"
    )
    return Unit(unit.name, unit.scale, unit.size, unit.why, warning)
