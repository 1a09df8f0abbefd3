"""Manipulation scripts: a valid script converts exactly; every bad input gives one precise line."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from puppetcli.errors import ScriptError
from puppetcli.rigfile import rig_from_text
from puppetcli.script import ACTION_PARSERS, Key, Push, Wait, load_script, script_from_text
from solver.spec import RigSpec

DOCS = Path(__file__).resolve().parents[2] / "docs"

RIG = """\
name: arm
bones:
  - {name: upper, head: [0, 1, 0], tail: [0.3, 1, 0]}
  - {name: forearm, parent: upper, head: [0.3, 1, 0], tail: [0.5, 1, 0]}
  - {name: hand, parent: forearm, head: [0.5, 1, 0], tail: [0.6, 1, 0]}
"""

VALID = """\
h: 0.02
duration: 6.0
gravity: false
solver: {method: pgs, iterations: 30, warm_start_factor: 0.5}
actions:
  - key: rest
  - push: {bone: forearm, torque: [0, 0, 1.0], duration: 2.0}
  - push:
      bone: hand
      force: [0, 5, 0]
      point: [0, 0.02, 0]
      duration: 5e-1
  - wait: 4.0
  - wait: {duration: 1}
  - key:
  - key: {}
  - key: {label: end}
"""


@pytest.fixture(scope="module")
def rig() -> RigSpec:
    return rig_from_text(RIG, "arm.yaml")


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "bend.yaml"
    path.write_text(text, encoding="utf-8")
    return path


def line_of(text: str, marker: str, nth: int = 1) -> int:
    """1-based line of the ``nth`` line containing ``marker`` (independent of the loader)."""
    hits = [i + 1 for i, line in enumerate(text.splitlines()) if marker in line]
    return hits[nth - 1]


def bad(tmp_path: Path, rig: RigSpec, old: str, new: str) -> tuple[str, str]:
    """VALID with one substitution: (ScriptError message, new text)."""
    assert old in VALID
    text = VALID.replace(old, new, 1)
    with pytest.raises(ScriptError) as info:
        load_script(write(tmp_path, text), rig)
    message = str(info.value)
    assert "\n" not in message
    return message, text


def expect(message: str, tmp_path: Path, line: int, path: str, *words: str) -> None:
    assert message.startswith(f"{tmp_path / 'bend.yaml'}:{line}: {path}: expected "), message
    for word in words:
        assert word in message, message


def test_valid_script_converts(tmp_path: Path, rig: RigSpec) -> None:
    script = load_script(write(tmp_path, VALID), rig)
    assert script.source == str(tmp_path / "bend.yaml")
    assert (script.h, script.duration, script.gravity) == (0.02, 6.0, False)
    assert script.solver == {"method": "pgs", "iterations": 30, "warm_start_factor": 0.5}
    assert [type(a) for a in script.actions] == [Key, Push, Push, Wait, Wait, Key, Key, Key]
    rest, twist, lift, wait4, wait1, key2, key3, end = script.actions
    assert rest == Key("rest", line_of(VALID, "key: rest"))
    assert twist.bone == "forearm" and twist.duration == 2.0
    np.testing.assert_array_equal(twist.torque, [0.0, 0.0, 1.0])
    np.testing.assert_array_equal(twist.force, np.zeros(3))
    np.testing.assert_array_equal(twist.point, np.zeros(3))
    assert twist.line == line_of(VALID, "bone: forearm")
    assert (
        lift.bone == "hand" and lift.duration == 0.5 and lift.line == line_of(VALID, "- push:", 2)
    )
    np.testing.assert_array_equal(lift.force, [0.0, 5.0, 0.0])
    np.testing.assert_array_equal(lift.point, [0.0, 0.02, 0.0])
    assert wait4 == Wait(4.0, line_of(VALID, "wait: 4.0"))
    assert wait1 == Wait(1.0, line_of(VALID, "wait: {duration"))
    assert (key2.label, key3.label, end.label) == ("key 2", "key 3", "end")
    assert key2.line == line_of(VALID, "- key:", 2)
    with pytest.raises(ValueError):
        lift.force[0] = 1.0  # a frozen action's vectors are read-only too


def test_defaults_without_optional_keys(rig: RigSpec) -> None:
    script = script_from_text("actions: []\n", "empty.yaml", rig)
    assert (script.h, script.duration, script.gravity, script.solver) == (None, None, True, {})
    assert script.actions == ()


def test_action_table_lists_the_actions() -> None:
    assert set(ACTION_PARSERS) == {"push", "wait", "key"}


def test_documented_example_loads(rig: RigSpec) -> None:
    doc = (DOCS / "script-format.md").read_text(encoding="utf-8")
    example = re.search(r"```yaml\n(.*?)```", doc, re.S).group(1)
    script = script_from_text(example, "script-format.md", rig)
    labels = [a.label for a in script.actions if isinstance(a, Key)]
    assert labels == ["rest", "loaded", "key 3", "released"]


def test_unknown_action_suggests(tmp_path: Path, rig: RigSpec) -> None:
    message, text = bad(tmp_path, rig, "- wait: 4.0", "- wiat: 4.0")
    expect(message, tmp_path, line_of(text, "wiat"), "actions[3].wiat", "got 'wiat'", "'wait'?")


@pytest.mark.parametrize(
    ("new", "got"),
    [("- {}", "got an empty mapping"), ("- {wait: 1, key: a}", "2 names: wait, key")],
)
def test_zero_or_two_action_names(tmp_path: Path, rig: RigSpec, new: str, got: str) -> None:
    message, text = bad(tmp_path, rig, "- wait: 4.0", new)
    expect(message, tmp_path, line_of(text, new), "actions[3]", "one action name", got)


def test_unknown_bone_suggests(tmp_path: Path, rig: RigSpec) -> None:
    message, text = bad(tmp_path, rig, "bone: forearm", "bone: forarm")
    expect(message, tmp_path, line_of(text, "forarm"), "actions[1].push.bone", "'forearm'?")


@pytest.mark.parametrize(
    ("old", "new", "path", "got"),
    [
        ("duration: 2.0}", "duration: 0}", "actions[1].push.duration", "got 0"),
        ("wait: 4.0", "wait: -4.0", "actions[3].wait", "got -4.0"),
        ("{duration: 1}", "{duration: -1}", "actions[4].wait.duration", "got -1"),
        ("duration: 6.0", "duration: 0.0", "duration", "got 0.0"),
        ("h: 0.02", "h: -0.02", "h", "got -0.02"),
    ],
)
def test_zero_or_negative_durations(
    tmp_path: Path, rig: RigSpec, old: str, new: str, path: str, got: str
) -> None:
    message, text = bad(tmp_path, rig, old, new)
    expect(message, tmp_path, line_of(text, new), path, "a positive finite number", got)


@pytest.mark.parametrize("value", [".nan", ".inf", "-.inf", "1e999"])
def test_non_finite_numbers(tmp_path: Path, rig: RigSpec, value: str) -> None:
    message, text = bad(tmp_path, rig, "torque: [0, 0, 1.0]", f"torque: [0, 0, {value}]")
    expect(message, tmp_path, line_of(text, value), "actions[1].push.torque[2]", f"got {value}")


@pytest.mark.parametrize(
    ("new", "path", "got"),
    [
        ("[0, 5]", "actions[2].push.force", "got a list of 2 items"),
        ("{x: 5}", "actions[2].push.force", "got a mapping"),
        ("[0, up, 0]", "actions[2].push.force[1]", "got 'up'"),
    ],
)
def test_malformed_vectors(tmp_path: Path, rig: RigSpec, new: str, path: str, got: str) -> None:
    message, text = bad(tmp_path, rig, "force: [0, 5, 0]", f"force: {new}")
    expect(message, tmp_path, line_of(text, "force:"), path, got)


def test_unknown_key_in_action_suggests(tmp_path: Path, rig: RigSpec) -> None:
    message, text = bad(tmp_path, rig, "force: [0, 5, 0]", "forse: [0, 5, 0]")
    expect(message, tmp_path, line_of(text, "forse"), "actions[2].push.forse", "'force'?")


def test_push_needs_force_or_torque(tmp_path: Path, rig: RigSpec) -> None:
    message, text = bad(tmp_path, rig, "torque: [0, 0, 1.0], ", "")
    expect(message, tmp_path, line_of(text, "bone: forearm"), "actions[1].push", "got neither")


def test_push_needs_bone_and_duration(tmp_path: Path, rig: RigSpec) -> None:
    message, text = bad(tmp_path, rig, "      duration: 5e-1\n", "")
    expect(message, tmp_path, line_of(text, "bone: hand"), "actions[2].push", "no 'duration' key")


def test_duplicate_key_label(tmp_path: Path, rig: RigSpec) -> None:
    message, text = bad(tmp_path, rig, "{label: end}", "{label: rest}")
    expect(message, tmp_path, line_of(text, "label: rest"), "actions[7].key.label", "unique")
    assert f"first at line {line_of(text, 'key: rest')}" in message


def test_key_label_must_be_a_string(tmp_path: Path, rig: RigSpec) -> None:
    message, text = bad(tmp_path, rig, "key: rest", "key: off")
    expect(message, tmp_path, line_of(text, "key: off"), "actions[0].key", "got boolean false")


def test_step_given_twice(tmp_path: Path, rig: RigSpec) -> None:
    message, _ = bad(tmp_path, rig, "{method: pgs,", "{h: 0.01, method: pgs,")
    expect(message, tmp_path, 1, "h", "either at the top level or in 'solver', got both")


def test_bad_solver_override(tmp_path: Path, rig: RigSpec) -> None:
    message, _ = bad(tmp_path, rig, "method: pgs", "methd: pgs")
    expect(message, tmp_path, 4, "solver.methd", "(did you mean 'method'?)")


def test_unknown_top_level_key_and_missing_actions(tmp_path: Path, rig: RigSpec) -> None:
    message, _ = bad(tmp_path, rig, "actions:", "action:")
    expect(message, tmp_path, 5, "action", "(did you mean 'actions'?)")
    with pytest.raises(ScriptError) as info:
        script_from_text("h: 0.01\n", "s.yaml", rig)
    assert (
        str(info.value)
        == "s.yaml:1: document: expected a value for 'actions', got no 'actions' key"
    )


def test_yaml_syntax_error_has_line(tmp_path: Path, rig: RigSpec) -> None:
    message, text = bad(tmp_path, rig, "  - wait: 4.0\n", "  - wait: 4.0\n bad: [\n")
    assert message.startswith(
        f"{tmp_path / 'bend.yaml'}:{line_of(text, 'bad: [')}: YAML syntax error"
    )
