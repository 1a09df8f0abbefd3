"""Manipulation scripts: YAML → a validated ``Script`` of timed actions.

The format is documented in ``docs/script-format.md``.  Actions run one after
another on one timeline: a ``push`` or ``wait`` advances it by its duration, a
``key`` marks the current instant as a keyframe.  Each action keeps the 1-based
line it came from so later stages (the runner, ``expect`` failures) can point
back into the file.

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
from puppetcli.rigfile import solver_overrides
from puppetcli.yamldoc import Node, did_you_mean, load_file, load_text
from solver.spec import RigSpec

__all__ = [
    "ACTION_PARSERS",
    "Action",
    "Key",
    "Push",
    "Script",
    "Wait",
    "load_script",
    "script_from_text",
]

TOP_KEYS = ("h", "duration", "gravity", "solver", "actions")
PUSH_KEYS = ("bone", "force", "torque", "point", "duration")


def _frozen_vector(values: np.ndarray) -> np.ndarray:
    """A read-only float copy, so a frozen action stays frozen."""
    out = np.array(values, dtype=float)
    out.setflags(write=False)
    return out


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


Action = Push | Wait | Key


@dataclass(frozen=True)
class Script:
    """A validated script.

    source: the file it came from.  h: step override (s) or None.
    duration: simulate at least this long (s) or None.  gravity: whether gravity acts.
    solver: ``SolverSpec`` field overrides (already converted).  actions: in timeline order.
    """

    source: str
    h: float | None
    duration: float | None
    gravity: bool
    solver: dict[str, Any] = field(default_factory=dict)
    actions: tuple[Action, ...] = ()


@dataclass
class ParseContext:
    """What an action parser may consult: the rig's bone names and the keys so far."""

    bones: tuple[str, ...]
    key_lines: dict[str, int] = field(default_factory=dict)

    def bone(self, node: Node) -> str:
        """Read a bone name that must exist in the rig."""
        name = node.string("a bone name")
        if name not in self.bones:
            node.fail("the name of a bone in the rig", hint=did_you_mean(name, self.bones))
        return name


def load_script(path: Path, rig: RigSpec) -> Script:
    """Read and validate a script against ``rig``; raises ``ScriptError``."""
    return _script_from_document(load_file(path, ScriptError), rig)


def script_from_text(text: str, source: str, rig: RigSpec) -> Script:
    """Validate script YAML ``text`` against ``rig``; ``source`` names it in errors."""
    return _script_from_document(load_text(text, source, ScriptError), rig)


def _script_from_document(doc: Node, rig: RigSpec) -> Script:
    top = doc.mapping(TOP_KEYS, required=("actions",), what="a mapping of script settings")
    solver = top.read("solver", solver_overrides, {})
    h = top.read("h", Node.positive, None)
    if h is not None and "h" in solver:
        top["h"].fail("'h' either at the top level or in 'solver'", got="both")
    context = ParseContext(tuple(bone.name for bone in rig.bones))
    actions = tuple(_parse_action(item, context) for item in top["actions"].items())
    return Script(
        source=doc.source,
        h=h,
        duration=top.read("duration", Node.positive, None),
        gravity=top.read("gravity", Node.boolean, True),
        solver=solver,
        actions=actions,
    )


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
        force=_frozen_vector(zero if force is None else force),
        torque=_frozen_vector(zero if torque is None else torque),
        point=_frozen_vector(fields.read("point", lambda n: n.vector(3), zero)),
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
}
