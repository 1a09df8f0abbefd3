"""Manipulation scripts: YAML → a validated ``Script`` of timed actions.

The format is documented in ``docs/script-format.md``.  Actions run one after
another on one timeline: a ``push``, ``wait`` or pointer motion advances it by
its duration, a ``key`` or ``expect`` acts at the current instant.  Each action
keeps the 1-based line it came from so later stages (the runner, ``expect``
failures) can point back into the file.  The pointer actions (``grip``, ``move``
…) live in ``puppetcli.script.actions``; the top-level ``pointer``,
``workspace`` and ``haptics`` blocks are read here.

Actions are parsed through ``ACTION_PARSERS``, a table from action name to
parser; adding an action means adding one dataclass, one parser and one entry.
Every problem is one ``ScriptError`` line: file, line, YAML path, expected, got.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from puppetcli.errors import ScriptError
from puppetcli.rig.load import read_step, solver_overrides
from puppetcli.script.actions import (
    Expect,
    Grip,
    Move,
    ParseContext,
    Release,
    Rotate,
    Touch,
    Twist,
    frozen_vector,
    parse_expect,
    parse_grip,
    parse_move,
    parse_release,
    parse_rotate,
    parse_touch,
    parse_twist,
)
from puppetcli.script.pins import Pin, Unpin, parse_pin, parse_unpin, rig_bones
from puppetcli.yamldoc import Fields, Node, did_you_mean, load_file, load_text
from solver.spec import RigSpec

__all__ = [
    "ACTION_PARSERS",
    "Action",
    "Expect",
    "Grip",
    "Key",
    "Move",
    "Pin",
    "Push",
    "Release",
    "Rotate",
    "Script",
    "Touch",
    "Twist",
    "Unpin",
    "Wait",
    "load_script",
    "script_from_text",
]

TOP_KEYS = ("h", "duration", "gravity", "solver", "pointer", "workspace", "haptics", "actions")
PUSH_KEYS = ("bone", "force", "torque", "point", "duration")
DEFAULT_POINTER_START = (0.0, 1.2, 0.6)  # m, world: in front of the doll's chest
DEFAULT_POINTER_RADIUS = 0.02  # m
DEFAULT_WORKSPACE_OFFSET = (0.0, 1.2, 0.3)  # m, world position of the device origin
DEFAULT_WORKSPACE_SCALE = 4.0  # world metres per device metre
DEFAULT_MAX_FORCE = 20.0  # N, device clamp
DEFAULT_MAX_TORQUE = 1.0  # N·m, device clamp
DEFAULT_LOWPASS = 0.0  # one-pole coefficient a: y = a·y_prev + (1 − a)·x; 0 = no filter


@dataclass(frozen=True)
class Push:
    """Apply a force and/or torque to a bone for ``duration`` s (the timeline advances by it).

    force: N, world frame, shape (3,); acts at ``point``.
    torque: N·m, world frame, shape (3,).
    point: m, shape (3,): bone-local point relative to the bone's head, in the bone's
        body frame (world-aligned at rest).
    """

    bone: str
    force: np.ndarray
    torque: np.ndarray
    point: np.ndarray
    duration: float
    line: int


@dataclass(frozen=True)
class Wait:
    """Let the simulation run untouched for ``duration`` s."""

    duration: float
    line: int


@dataclass(frozen=True)
class Key:
    """Keep the current state as the keyframe ``label``."""

    label: str
    line: int


Action = Push | Wait | Key | Grip | Move | Rotate | Twist | Release | Touch | Expect | Pin | Unpin


@dataclass(frozen=True)
class Script:
    """A validated script.

    source: the file it came from.  h: step override (s) or None.
    duration: simulate at least this long (s) or None.  gravity: whether gravity acts.
    solver: ``SolverSpec`` field overrides (already converted).  actions: in timeline order.
    pointer_start: m, world, shape (3,): where the pointer starts.
    pointer_radius: m: the pointer's contact sphere.
    workspace_offset (m, world, shape (3,)) and workspace_scale (> 0): the device-to-world
        map, world = workspace_offset + workspace_scale × device.
    max_force (N), max_torque (N·m): the device's output clamp.
    lowpass: one-pole low-pass coefficient a in [0, 1) on the device output,
        y = a·y_prev + (1 − a)·x (0 = no filtering).
    """

    source: str
    h: float | None
    duration: float | None
    gravity: bool
    solver: dict[str, Any] = field(default_factory=dict)
    actions: tuple[Action, ...] = ()
    pointer_start: np.ndarray = field(default_factory=lambda: frozen_vector(DEFAULT_POINTER_START))
    pointer_radius: float = DEFAULT_POINTER_RADIUS
    workspace_offset: np.ndarray = field(
        default_factory=lambda: frozen_vector(DEFAULT_WORKSPACE_OFFSET)
    )
    workspace_scale: float = DEFAULT_WORKSPACE_SCALE
    max_force: float = DEFAULT_MAX_FORCE
    max_torque: float = DEFAULT_MAX_TORQUE
    lowpass: float = DEFAULT_LOWPASS


def load_script(path: Path, rig: RigSpec) -> Script:
    """Read and validate a script against ``rig``; raises ``ScriptError``."""
    return _script_from_document(load_file(path, ScriptError), rig)


def script_from_text(text: str, source: str, rig: RigSpec) -> Script:
    """Validate script YAML ``text`` against ``rig``; ``source`` names it in errors."""
    return _script_from_document(load_text(text, source, ScriptError), rig)


def _script_from_document(doc: Node, rig: RigSpec) -> Script:
    top = doc.mapping(TOP_KEYS, required=("actions",), what="a mapping of script settings")
    solver = top.read("solver", solver_overrides, {})
    h = top.read("h", read_step, None)
    if h is not None and "h" in solver:
        top["h"].fail("'h' either at the top level or in 'solver'", got="both")
    context = _context(rig)
    actions = tuple(_parse_action(item, context) for item in top["actions"].items())
    return Script(
        source=doc.source,
        h=h,
        duration=top.read("duration", Node.positive, None),
        gravity=top.read("gravity", Node.boolean, True),
        solver=solver,
        actions=actions,
        **_settings(top),
    )


def _context(rig: RigSpec) -> ParseContext:
    """Bone and joint names of ``rig``: every non-root bone has a joint, a root only if 'ball'."""
    root = next(bone.name for bone in rig.bones if bone.parent is None)
    joints = tuple(
        bone.name for bone in rig.bones if bone.parent is not None or rig.root_mode == "ball"
    )
    names = tuple(b.name for b in rig.bones)
    return ParseContext(names, joints, root, rig.root_mode, rig_bones=rig_bones(rig))


def _lowpass(node: Node) -> float:
    value = node.number(0.0, 1.0)
    if value >= 1.0:  # a = 1 would hold the first sample forever
        node.fail("a number in [0, 1)")
    return value


# Top-level block → its keys → (Script field, reader).
_SETTINGS: dict[str, dict[str, tuple[str, Callable[[Node], Any]]]] = {
    "pointer": {
        "start": ("pointer_start", lambda node: frozen_vector(node.vector(3))),
        "radius": ("pointer_radius", Node.positive),
    },
    "workspace": {
        "offset": ("workspace_offset", lambda node: frozen_vector(node.vector(3))),
        "scale": ("workspace_scale", Node.positive),
    },
    "haptics": {
        "max_force": ("max_force", Node.positive),
        "max_torque": ("max_torque", Node.positive),
        "lowpass": ("lowpass", _lowpass),
    },
}


def _settings(top: Fields) -> dict[str, Any]:
    """``Script`` fields from the pointer, workspace and haptics blocks (only keys given)."""
    out: dict[str, Any] = {}
    for block, readers in _SETTINGS.items():
        if (node := top.get(block)) is None:
            continue
        fields = node.mapping(tuple(readers), what=f"a {block} mapping")
        for key in fields:
            if (value := fields.get(key)) is not None:
                name, reader = readers[key]
                out[name] = reader(value)
    return out


def _parse_action(item: Node, context: ParseContext) -> Action:
    """Dispatch one ``- name: body`` list item to its parser."""
    names = ", ".join(ACTION_PARSERS)
    expected = f"a mapping with one action name ({names})"
    if not isinstance(item.node, yaml.MappingNode) or not item.node.value:
        item.fail(expected)
    if len(item.node.value) > 1:
        keys = ", ".join(str(key.value) for key, _ in item.node.value)
        item.fail(expected, got=f"{len(item.node.value)} names: {keys}")
    key_node, body_node = item.node.value[0]
    key = item.child(key_node, str(key_node.value))
    name = key.value()
    if not isinstance(name, str) or name not in ACTION_PARSERS:
        key.fail(
            f"an action name ({names})", hint=did_you_mean(str(key_node.value), ACTION_PARSERS)
        )
    context.here = key
    return ACTION_PARSERS[name](item.child(body_node, name), item.line, context)


def _parse_push(node: Node, line: int, context: ParseContext) -> Push:
    fields = node.mapping(PUSH_KEYS, required=("bone", "duration"), what="a push mapping")
    bone = context.bone(fields["bone"])
    force = fields.read("force", lambda n: n.vector(3), None)
    torque = fields.read("torque", lambda n: n.vector(3), None)
    if force is None and torque is None:
        node.fail("a 'force' or a 'torque'", got="neither")
    zero = np.zeros(3)
    return Push(
        bone=bone,
        force=frozen_vector(zero if force is None else force),
        torque=frozen_vector(zero if torque is None else torque),
        point=frozen_vector(fields.read("point", lambda n: n.vector(3), zero)),
        duration=fields["duration"].positive(),
        line=line,
    )


def _parse_wait(node: Node, line: int, context: ParseContext) -> Wait:
    if isinstance(node.node, yaml.MappingNode):
        node = node.mapping(("duration",), required=("duration",))["duration"]
    return Wait(duration=node.positive(), line=line)


def _parse_key(node: Node, line: int, context: ParseContext) -> Key:
    label_node: Node | None = node
    if isinstance(node.node, yaml.MappingNode):
        label_node = node.mapping(("label",)).get("label")
    elif node.is_null():
        label_node = None
    label = (
        f"key {len(context.key_lines) + 1}"
        if label_node is None
        else label_node.string("a key label (a string)")
    )
    if label in context.key_lines:
        (label_node or node).fail(
            "a unique key label", got=f"'{label}' again (first at line {context.key_lines[label]})"
        )
    context.key_lines[label] = line
    return Key(label=label, line=line)


ActionParser = Callable[[Node, int, ParseContext], Action]

ACTION_PARSERS: dict[str, ActionParser] = {
    "push": _parse_push,
    "wait": _parse_wait,
    "key": _parse_key,
    "grip": parse_grip,
    "move": parse_move,
    "rotate": parse_rotate,
    "twist": parse_twist,
    "release": parse_release,
    "touch": parse_touch,
    "expect": parse_expect,
    "pin": parse_pin,
    "unpin": parse_unpin,
}
