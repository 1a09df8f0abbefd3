"""Pointer actions of manipulation scripts: grip, move, rotate, twist, release, touch, expect.

The haptic pointer is in one of two modes along the timeline: *free* (it is a
small sphere that pushes what it meets) or *gripping* one bone (a spring-damper
couples it to a point of that bone).  ``grip`` enters the gripping mode and
``release`` leaves it; ``twist`` needs a grip, ``touch`` needs a free pointer.
The parse tracks the mode through the action list, so an impossible sequence is
reported at load time, on the offending action's line.

Units as in the file format (``docs/script-format.md``): positions are world
coordinates in metres (Y up); angles are degrees in the file and radians here;
durations are seconds > 0.  ``ParseContext`` (the rig's names and the mode so
far) is shared with the parsers of ``puppetcli.script.load``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import yaml

from puppetcli.yamldoc import Fields, Node, did_you_mean

__all__ = [
    "GRIP_DEFAULTS",
    "Expect",
    "Grip",
    "Move",
    "ParseContext",
    "Release",
    "Rotate",
    "Touch",
    "Twist",
    "frozen_vector",
]

GRIP_DEFAULTS = {
    "reach": 0.15,  # m
    "stiffness": 2000.0,  # N/m
    "damping": 40.0,  # N·s/m
    "rot_stiffness": 50.0,  # N·m/rad
    "rot_damping": 2.0,  # N·m·s/rad
    "force_limit": 300.0,  # N
    "torque_limit": 30.0,  # N·m
}
GRIP_KEYS = ("bone", "nearest", "point", *GRIP_DEFAULTS, "position_only")
DEFAULT_ANGLE_TOLERANCE = math.radians(5.0)
DEFAULT_HEAD_TOLERANCE = 0.02  # m
EXPECT_ANGLE_KEYS = ("angle", "rotation", "min_angle", "max_angle")
EXPECT_KEYS = ("joint", "bone", *EXPECT_ANGLE_KEYS, "head", "tolerance")


def frozen_vector(values: np.ndarray) -> np.ndarray:
    """A read-only float copy, so a frozen action stays frozen."""
    out = np.array(values, dtype=float)
    out.setflags(write=False)
    return out


@dataclass(frozen=True)
class Grip:
    """Couple the pointer to a bone by a 6-DOF spring-damper (translation only if position_only).

    bone: the bone to grip, or None for the bone nearest the pointer within ``reach`` (m).
    point: m, shape (3,), read-only: bone-local point relative to the bone's head, in the
        bone's body frame (world-aligned at rest); None = the bone's point closest to the
        pointer when the grip starts.
    stiffness N/m, damping N·s/m, rot_stiffness N·m/rad, rot_damping N·m·s/rad: the coupling.
    force_limit N, torque_limit N·m: clamps on the coupling's force and torque.
    """

    bone: str | None
    point: np.ndarray | None
    reach: float
    stiffness: float
    damping: float
    rot_stiffness: float
    rot_damping: float
    force_limit: float
    torque_limit: float
    position_only: bool
    line: int


@dataclass(frozen=True)
class Move:
    """Move the pointer along a minimum-jerk path over ``duration`` s (free or gripping).

    to: world position (m), shape (3,), or None; by: world displacement (m), shape (3,),
    or None.  Exactly one is set.
    """

    to: np.ndarray | None
    by: np.ndarray | None
    duration: float
    line: int


@dataclass(frozen=True)
class Rotate:
    """Turn the pointer by ``angle`` rad about the world unit ``axis`` (3,) through the pointer."""

    axis: np.ndarray
    angle: float
    duration: float
    line: int


@dataclass(frozen=True)
class Twist:
    """Turn the pointer by ``angle`` rad about the gripped bone's head→tail axis (gripping only)."""

    angle: float
    duration: float
    line: int


@dataclass(frozen=True)
class Release:
    """Let go of the gripped bone; the pointer is free again."""

    line: int


@dataclass(frozen=True)
class Touch:
    """A free-mode ``Move``: the pointer sphere pushes whatever it meets on the way.

    to: world position (m), shape (3,), or None; by: world displacement (m), or None.
    """

    to: np.ndarray | None
    by: np.ndarray | None
    duration: float
    line: int


@dataclass(frozen=True)
class Expect:
    """Check the simulated pose at this instant of the timeline.

    Joint form (``joint`` set, ``bone`` None): ``angle`` (rad) is the joint's total rotation
    angle from rest, ``rotation`` (rad, shape (3,)) its rotation vector in the parent frame;
    both compared within ``tolerance`` (rad).  ``min_angle``/``max_angle`` (rad) are exact
    bounds on the total angle.  Bone form (``bone`` set): ``head`` is the bone head's
    world position (m, shape (3,)), compared within ``tolerance`` (m, Euclidean distance).
    """

    joint: str | None
    bone: str | None
    angle: float | None
    rotation: np.ndarray | None
    head: np.ndarray | None
    min_angle: float | None
    max_angle: float | None
    tolerance: float
    line: int


@dataclass
class ParseContext:
    """What an action parser may consult: the rig's names, the key labels and the pointer mode.

    here: the current action's name node (path ``actions[i].<name>``, the action's line),
    set by the dispatcher; sequence errors are reported on it.
    grip_line: line of the grip in force, or None while the pointer is free.
    """

    bones: tuple[str, ...]
    joints: tuple[str, ...] = ()
    root: str = ""
    root_mode: str = "fixed"
    key_lines: dict[str, int] = field(default_factory=dict)
    here: Node | None = None
    grip_line: int | None = None
    grip_bone: str | None = None
    pinned: dict[str, int] = field(default_factory=dict)  # bone → line of its pin
    rig_bones: dict = field(default_factory=dict)  # name → solver.spec.BoneSpec

    def bone(self, node: Node) -> str:
        """Read a bone name that must exist in the rig."""
        name = node.string("a bone name")
        if name not in self.bones:
            node.fail("the name of a bone in the rig", hint=did_you_mean(name, self.bones))
        return name

    def joint(self, node: Node) -> str:
        """Read a joint name (a bone's name; a root has a joint only with ``root: ball``)."""
        name = node.string("a joint name")
        if name not in self.joints:
            hint = did_you_mean(name, self.joints)
            if name == self.root:
                hint = f" (the {self.root_mode} root has no joint; only a 'ball' root has one)"
            node.fail("the name of a joint in the rig", hint=hint)
        return name

    def gripping(self) -> str:
        """Words for the grip in force (for 'got …' in sequence errors)."""
        what = "the nearest bone" if self.grip_bone is None else f"'{self.grip_bone}'"
        return f"{what} (gripped at line {self.grip_line})"

    def need_free(self, expected: str, action: str) -> None:
        """Fail on the current action unless the pointer is free."""
        assert self.here is not None, "set by the dispatcher"
        if self.grip_line is not None:
            self.here.fail(expected, got=f"a {action} while gripping {self.gripping()}")

    def need_grip(self, expected: str, action: str) -> None:
        """Fail on the current action unless the pointer grips a bone."""
        assert self.here is not None, "set by the dispatcher"
        if self.grip_line is None:
            self.here.fail(expected, got=f"a {action} while the pointer is free (nothing gripped)")


def degrees(node: Node, minimum: float | None = None, maximum: float | None = None) -> float:
    """Read an angle in degrees (within the bounds, in degrees); returns radians."""
    return math.radians(node.number(minimum, maximum))


def _vector3(node: Node) -> np.ndarray:
    return frozen_vector(node.vector(3))


def _either(fields: Fields, node: Node, first: str, second: str, neither: str = "") -> str:
    """The one of two mutually exclusive keys that is given (null counts as absent).

    ``neither``: what to ask for when both are missing (default "a 'first' or a 'second'").
    """
    has_first, has_second = fields.get(first) is not None, fields.get(second) is not None
    if has_first and has_second:
        fields.key_node(second).fail(f"either '{first}' or '{second}'", got="both")
    if not (has_first or has_second):
        node.fail(neither or f"a '{first}' or a '{second}'", got="neither")
    return first if has_first else second


def _only_with(fields: Fields, keys: tuple[str, ...], allowed: str, needs: str) -> None:
    """Keys of ``keys`` present in ``fields`` are errors unless ``allowed``."""
    for key in keys:
        if key in fields:
            fields.key_node(key).fail(f"'{key}' only {needs}", got=f"it with {allowed}")


def parse_grip(node: Node, line: int, context: ParseContext) -> Grip:
    context.need_free("a release before gripping again", "grip")
    if isinstance(node.node, yaml.ScalarNode) and not node.is_null():
        bone, fields = context.bone(node), None  # the short form ``grip: forearm_l``
    else:
        fields = node.mapping(GRIP_KEYS, what="a bone name or a grip mapping")
        bone = _grip_bone(fields, node, context)
    values, point, position_only = dict(GRIP_DEFAULTS), None, False
    if fields is not None:
        for key, default in GRIP_DEFAULTS.items():
            reader = Node.non_negative if key.endswith("damping") else Node.positive
            values[key] = fields.read(key, reader, default)
        point = fields.read("point", _vector3, None)
        position_only = fields.read("position_only", Node.boolean, False)
    context.grip_line, context.grip_bone = line, bone
    return Grip(bone=bone, point=point, position_only=position_only, line=line, **values)


def _grip_bone(fields: Fields, node: Node, context: ParseContext) -> str | None:
    """The named bone, or None for ``nearest: true`` (exactly one of the two)."""
    if _either(fields, node, "bone", "nearest", "a 'bone' or 'nearest: true'") == "bone":
        _only_with(fields, ("reach",), "a named 'bone'", "with 'nearest: true'")
        return context.bone(fields["bone"])
    _only_with(fields, ("point",), "'nearest: true'", "with a named 'bone'")
    nearest = fields["nearest"]
    if not nearest.boolean():
        nearest.fail("true (or a 'bone' instead of 'nearest')")
    return None


def _target(node: Node, what: str) -> tuple[np.ndarray | None, np.ndarray | None, float]:
    """``to``/``by`` (exactly one) and ``duration`` of a move or a touch."""
    fields = node.mapping(("to", "by", "duration"), required=("duration",), what=what)
    key = _either(fields, node, "to", "by")
    vector = _vector3(fields[key])
    duration = fields["duration"].positive()
    return (vector, None, duration) if key == "to" else (None, vector, duration)


def parse_move(node: Node, line: int, context: ParseContext) -> Move:
    to, by, duration = _target(node, "a move mapping")
    return Move(to=to, by=by, duration=duration, line=line)


def parse_touch(node: Node, line: int, context: ParseContext) -> Touch:
    context.need_free("a release before a touch (a touch is a free-pointer move)", "touch")
    to, by, duration = _target(node, "a touch mapping")
    return Touch(to=to, by=by, duration=duration, line=line)


def parse_rotate(node: Node, line: int, context: ParseContext) -> Rotate:
    keys = ("axis", "angle", "duration")
    fields = node.mapping(keys, required=keys, what="a rotate mapping")
    axis_node = fields["axis"]
    axis = axis_node.vector(3)
    norm = float(np.linalg.norm(axis))
    if norm < 1e-9:
        shown = ", ".join(f"{a:g}" for a in axis)
        axis_node.fail("a non-zero rotation axis", got=f"[{shown}]")
    return Rotate(
        axis=frozen_vector(axis / norm),
        angle=degrees(fields["angle"]),
        duration=fields["duration"].positive(),
        line=line,
    )


def parse_twist(node: Node, line: int, context: ParseContext) -> Twist:
    context.need_grip("a grip before a twist (it turns about the gripped bone's axis)", "twist")
    keys = ("angle", "duration")
    fields = node.mapping(keys, required=keys, what="a twist mapping")
    return Twist(degrees(fields["angle"]), fields["duration"].positive(), line)


def parse_release(node: Node, line: int, context: ParseContext) -> Release:
    context.need_grip("a grip before a release", "release")
    empty = isinstance(node.node, yaml.MappingNode) and not node.node.value
    if not (node.is_null() or empty):
        node.fail("nothing after 'release:' (or an empty mapping {})")
    context.grip_line = context.grip_bone = None
    return Release(line)


def parse_expect(node: Node, line: int, context: ParseContext) -> Expect:
    fields = node.mapping(EXPECT_KEYS, what="an expect mapping")
    if _either(fields, node, "joint", "bone") == "bone":
        _only_with(fields, EXPECT_ANGLE_KEYS, "a 'bone'", "with a 'joint'")
        if fields.get("head") is None:
            node.fail("a 'head' position to check for the 'bone'", got="no 'head' key")
        return Expect(
            joint=None,
            bone=context.bone(fields["bone"]),
            angle=None,
            rotation=None,
            head=_vector3(fields["head"]),
            min_angle=None,
            max_angle=None,
            tolerance=fields.read("tolerance", Node.positive, DEFAULT_HEAD_TOLERANCE),
            line=line,
        )
    _only_with(fields, ("head",), "a 'joint'", "with a 'bone'")
    joint = context.joint(fields["joint"])
    angle, rotation, low, high = _expected_angles(fields, node)
    if (low is not None or high is not None) and "tolerance" in fields:
        fields.key_node("tolerance").fail(
            "'tolerance' only with 'angle' or 'rotation' (min_angle/max_angle are exact bounds)",
            got="it with min_angle/max_angle",
        )
    tolerance = fields.read(
        "tolerance", lambda n: math.radians(n.positive()), DEFAULT_ANGLE_TOLERANCE
    )
    return Expect(joint, None, angle, rotation, None, low, high, tolerance, line)


def _expected_angles(
    fields: Fields, node: Node
) -> tuple[float | None, np.ndarray | None, float | None, float | None]:
    """angle | rotation | min_angle and/or max_angle (radians), exactly one of the three forms."""
    given = [key for key in EXPECT_ANGLE_KEYS if fields.get(key) is not None]
    if not given:
        node.fail("one of 'angle', 'rotation', 'min_angle', 'max_angle'", got="none of them")
    if len(given) > 1 and set(given) != {"min_angle", "max_angle"}:
        fields.key_node(given[1]).fail(
            "one of 'angle', 'rotation' or 'min_angle'/'max_angle'",
            got=f"both '{given[0]}' and '{given[1]}'",
        )
    angle = fields.read("angle", lambda n: degrees(n, 0.0, 180.0), None)
    rotation = fields.read("rotation", _rotation_vector, None)
    low = fields.read("min_angle", lambda n: degrees(n, 0.0, 180.0), None)
    high = fields.read("max_angle", lambda n: degrees(n, 0.0, 180.0), None)
    if low is not None and high is not None and low > high:
        shown = f"min_angle {math.degrees(low):g} > max_angle {math.degrees(high):g}"
        fields["max_angle"].fail("max_angle >= min_angle", got=shown)
    return angle, rotation, low, high


def _rotation_vector(node: Node) -> np.ndarray:
    """A rotation vector in degrees (magnitude at most 180) → radians."""
    vector = node.vector(3)
    magnitude = float(np.linalg.norm(vector))
    if magnitude > 180.0:
        node.fail("a rotation vector of at most 180 degrees", got=f"{magnitude:g} degrees")
    return frozen_vector(np.radians(vector))
