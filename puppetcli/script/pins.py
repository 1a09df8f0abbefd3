"""Pin actions of manipulation scripts: ``pin`` a bone (or a point of it) where it is,
``unpin`` it (or ``all``).

A pin holds until unpinned, through grips, releases, touches and waits (solver.rows.pin).
The parse tracks which bones are pinned (``ParseContext.pinned``), so pinning a bone twice
or unpinning one that is not pinned is reported at load time on the action's line.

``point`` is in metres, relative to the bone's head in the bone's body frame
(world-aligned at rest), as a grip's ``point``; it must lie inside the bone's shape.
Limits are finite and > 0: force_limit N per world axis, torque_limit N·m per axis.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import yaml

from puppetcli.script.actions import ParseContext, frozen_vector
from puppetcli.yamldoc import Node
from solver import quat
from solver.massprops import shape_frame
from solver.spec import BoneSpec, RigSpec

PIN_KEYS = ("bone", "point", "orient", "force_limit", "torque_limit")
ALL = "all"
INSIDE_SLACK = 1e-9  # m: a point on the surface is inside


@dataclass(frozen=True)
class Pin:
    """Hold ``bone`` where it is: the point ``point`` (m, (3,), read-only, from the bone's
    head in its body frame; None = its centre of mass), and its orientation too when
    ``orient``.  force_limit N and torque_limit N·m per world axis (inf: none); beyond
    them the pin slips (solver.rows.pin)."""

    bone: str
    point: np.ndarray | None
    orient: bool
    force_limit: float
    torque_limit: float
    line: int


@dataclass(frozen=True)
class Unpin:
    """Let go of the pin on ``bone`` (None: every pin)."""

    bone: str | None
    line: int


def parse_pin(node: Node, line: int, context: ParseContext) -> Pin:
    if isinstance(node.node, yaml.ScalarNode) and not node.is_null():
        bone, fields = context.bone(node), None  # the short form ``pin: foot_l``
    else:
        fields = node.mapping(PIN_KEYS, required=("bone",), what="a bone name or a pin mapping")
        bone = context.bone(fields["bone"])
    if bone in context.pinned:
        (node if fields is None else fields["bone"]).fail(
            f"an unpin before pinning '{bone}' again",
            got=f"'{bone}' pinned since line {context.pinned[bone]}",
        )
    point, orient, limits = None, False, {"force_limit": np.inf, "torque_limit": np.inf}
    if fields is not None:
        point = fields.read("point", lambda n: _point_on(n, context.rig_bones[bone]), None)
        orient = fields.read("orient", Node.boolean, False)
        for key in limits:
            limits[key] = fields.read(key, Node.positive, np.inf)
    context.pinned[bone] = line
    return Pin(bone, point, orient, line=line, **limits)


def parse_unpin(node: Node, line: int, context: ParseContext) -> Unpin:
    name = node.string("a bone name or 'all'")
    if name == ALL:
        if not context.pinned:
            node.fail("a pinned bone to unpin", got="'all' with no bone pinned")
        context.pinned.clear()
        return Unpin(None, line)
    bone = context.bone(node)
    if bone not in context.pinned:
        pinned = ", ".join(f"'{b}'" for b in context.pinned) or "none"
        node.fail("a pinned bone (or 'all')", got=f"'{bone}', not pinned (pinned: {pinned})")
    del context.pinned[bone]
    return Unpin(bone, line)


def _point_on(node: Node, bone: BoneSpec) -> np.ndarray:
    """A point (from the head, m) inside ``bone``'s shape."""
    point = node.vector(3)
    outside = outside_by(bone, point)
    if outside > INSIDE_SLACK:
        shown = ", ".join(f"{v:g}" for v in point)
        node.fail(
            f"a point inside the bone's {bone.shape.kind} (from its head, metres)",
            got=f"[{shown}], {outside:.3g} m outside it",
        )
    return frozen_vector(point)


def outside_by(bone: BoneSpec, point: np.ndarray) -> float:
    """How far (m) ``point`` (from the bone's head, rest pose) lies outside the bone's
    shape (≤ 0 inside), with the shape placed as solver.model places it."""
    shape = bone.shape
    centre = 0.5 * (bone.head + bone.tail)
    if shape.kind == "sphere" and bone.com is not None:
        centre = np.asarray(bone.com, dtype=float)
    local = quat.rotate(quat.conj(shape_frame(bone.head, bone.tail)), bone.head + point - centre)
    if shape.kind == "box":
        return float(np.max(np.abs(local) - np.asarray(shape.half_extents)))
    if shape.kind == "capsule":
        half = 0.5 * float(np.linalg.norm(bone.tail - bone.head))
        local = local - [0.0, np.clip(local[1], -half, half), 0.0]
    return float(np.linalg.norm(local) - shape.radius)


def rig_bones(rig: RigSpec) -> dict[str, BoneSpec]:
    """The rig's bones by name (what ``parse_pin`` checks points against)."""
    return {bone.name: bone for bone in rig.bones}
