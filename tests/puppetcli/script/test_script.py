"""Manipulation scripts: a valid script converts exactly; every bad input gives one precise line."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

from puppetcli.errors import ScriptError
from puppetcli.rig.load import load_rig, rig_from_text
from puppetcli.script.load import (
    ACTION_PARSERS,
    Expect,
    Grip,
    Key,
    Move,
    Push,
    Release,
    Rotate,
    Touch,
    Twist,
    Wait,
    load_script,
    script_from_text,
)
from solver.spec import RigSpec

ROOT = Path(__file__).resolve().parents[3]
DOCS = ROOT / "docs"

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


def bad(tmp_path: Path, rig: RigSpec, old: str, new: str, base: str = VALID) -> tuple[str, str]:
    """``base`` with one substitution: (ScriptError message, new text)."""
    assert old in base
    text = base.replace(old, new, 1)
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
    assert set(ACTION_PARSERS) == {
        "push",
        "wait",
        "key",
        "grip",
        "move",
        "rotate",
        "twist",
        "release",
        "touch",
        "expect",
        "pin",
        "unpin",
    }


def test_documented_example_loads() -> None:
    doc = (DOCS / "script-format.md").read_text(encoding="utf-8")
    example = re.search(r"```yaml\n(.*?)```", doc, re.S).group(1)
    script = script_from_text(example, "script-format.md", load_rig(ROOT / "rigs" / "doll.yaml"))
    labels = [a.label for a in script.actions if isinstance(a, Key)]
    assert labels == ["rest", "bent", "held", "key 4"]
    kinds = {type(a) for a in script.actions}
    assert kinds == {Key, Push, Wait, Grip, Move, Rotate, Twist, Release, Touch, Expect}
    np.testing.assert_array_equal(script.pointer_start, [0.6, 1.36, 0.25])
    assert (script.max_force, script.max_torque, script.lowpass) == (20.0, 1.0, 0.3)


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
    ],
)
def test_zero_or_negative_durations(
    tmp_path: Path, rig: RigSpec, old: str, new: str, path: str, got: str
) -> None:
    message, text = bad(tmp_path, rig, old, new)
    expect(message, tmp_path, line_of(text, new), path, "a positive finite number", got)


@pytest.mark.parametrize("new", ["h: -0.02", "h: 0", "h: 0.5", "h: 1e-7"])
def test_step_outside_its_range(tmp_path: Path, rig: RigSpec, new: str) -> None:
    """A step h outside [1e-5, 0.1] s is refused where it is read, the range in the line."""
    message, text = bad(tmp_path, rig, "h: 0.02", new)
    got = f"got {new.split()[1]}"
    expect(message, tmp_path, line_of(text, new), "h", "a number in [1e-05, 0.1]", got)


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


# --- The haptic pointer: settings, actions and their order --------------------------------

POINTER = """\
pointer: {start: [0.1, 1.1, 0.2], radius: 0.03}
workspace: {offset: [0, 1, 0.5], scale: 2.5}
haptics: {max_force: 15, max_torque: 0.5, lowpass: 0.25}
actions:
  - grip:
      bone: forearm
      point: [0.2, 0, 0]
      stiffness: 1500
      damping: 0
      rot_stiffness: 40
      rot_damping: 1.5
      force_limit: 200
      torque_limit: 20
      position_only: true
  - move: {to: [0.4, 1.2, 0], duration: 1.5}
  - rotate: {axis: [0, 3, 4], angle: 90, duration: 0.5}
  - twist: {angle: -45, duration: 2}
  - release:
  - touch: {by: [0, -0.1, 0], duration: 0.25}
  - move: {by: [0.1, 0, 0], duration: 1}
  - grip: forearm
  - release: {}
  - grip: {nearest: true, reach: 0.1}
  - wait: 0.5
  - expect: {joint: forearm, angle: 30, tolerance: 4}
  - expect: {joint: hand, min_angle: 20}
  - expect: {joint: forearm, min_angle: 10, max_angle: 50}
  - expect: {joint: forearm, rotation: [0, 0, 45], tolerance: 9}
  - expect: {joint: hand, max_angle: 60}
  - expect: {bone: hand, head: [0.5, 1.6, 0.0], tolerance: 0.03}
  - expect: {bone: upper, head: [0, 1, 0]}
"""

DEG = math.pi / 180.0


def test_pointer_settings_convert(rig: RigSpec) -> None:
    script = script_from_text(POINTER, "p.yaml", rig)
    np.testing.assert_array_equal(script.pointer_start, [0.1, 1.1, 0.2])
    np.testing.assert_array_equal(script.workspace_offset, [0.0, 1.0, 0.5])
    assert (script.pointer_radius, script.workspace_scale) == (0.03, 2.5)
    assert (script.max_force, script.max_torque, script.lowpass) == (15.0, 0.5, 0.25)
    with pytest.raises(ValueError):
        script.pointer_start[0] = 0.0


def test_pointer_settings_default(rig: RigSpec) -> None:
    script = script_from_text("haptics: {lowpass: 0.5}\nactions: []\n", "d.yaml", rig)
    np.testing.assert_array_equal(script.pointer_start, [0.0, 1.2, 0.6])
    np.testing.assert_array_equal(script.workspace_offset, [0.0, 1.2, 0.3])
    assert (script.pointer_radius, script.workspace_scale) == (0.02, 4.0)
    assert (script.max_force, script.max_torque, script.lowpass) == (20.0, 1.0, 0.5)


def test_pointer_actions_convert(rig: RigSpec) -> None:
    actions = script_from_text(POINTER, "p.yaml", rig).actions
    kinds = [Grip, Move, Rotate, Twist, Release, Touch, Move, Grip, Release, Grip, Wait]
    assert [type(a) for a in actions] == kinds + [Expect] * 7
    full, to, rotate, twist, release, touch, by, _, release2 = actions[:9]
    line = line_of(POINTER, "- grip:")
    assert full == Grip(
        "forearm", full.point, 0.15, 1500.0, 0.0, 40.0, 1.5, 200.0, 20.0, True, line
    )
    np.testing.assert_array_equal(full.point, [0.2, 0.0, 0.0])
    assert (to.by, to.duration, to.line) == (None, 1.5, line_of(POINTER, "move: {to"))
    np.testing.assert_array_equal(to.to, [0.4, 1.2, 0.0])
    np.testing.assert_allclose(rotate.axis, [0.0, 0.6, 0.8], rtol=0, atol=1e-15)
    assert rotate.angle == pytest.approx(math.pi / 2, abs=1e-15) and rotate.duration == 0.5
    assert twist == Twist(pytest.approx(-math.pi / 4, abs=1e-15), 2.0, line_of(POINTER, "twist"))
    assert release == Release(line_of(POINTER, "release:"))
    assert release2 == Release(line_of(POINTER, "release: {}"))
    assert (touch.to, touch.duration, touch.line) == (None, 0.25, line_of(POINTER, "touch"))
    np.testing.assert_array_equal(touch.by, [0.0, -0.1, 0.0])
    assert by.to is None and by.line == line_of(POINTER, "move: {by")
    np.testing.assert_array_equal(by.by, [0.1, 0.0, 0.0])
    with pytest.raises(ValueError):
        rotate.axis[0] = 1.0


def test_grip_short_form_and_nearest_take_defaults(rig: RigSpec) -> None:
    actions = script_from_text(POINTER, "p.yaml", rig).actions
    short, nearest = actions[7], actions[9]
    defaults = (None, 0.15, 2000.0, 40.0, 50.0, 2.0, 300.0, 30.0, False)
    assert short == Grip("forearm", *defaults, line_of(POINTER, "grip: forearm"))
    assert nearest == Grip(None, None, 0.1, *defaults[2:], line_of(POINTER, "nearest"))


def test_expect_converts_degrees_and_defaults(rig: RigSpec) -> None:
    expects = script_from_text(POINTER, "p.yaml", rig).actions[11:]
    angle, low, band, rotation, high, head, upper = expects
    assert angle == Expect(
        "forearm",
        None,
        pytest.approx(math.pi / 6),
        None,
        None,
        None,
        None,
        pytest.approx(4 * DEG),
        line_of(POINTER, "angle: 30"),
    )
    assert (low.joint, low.min_angle, low.max_angle, low.angle) == ("hand", 20 * DEG, None, None)
    assert low.tolerance == pytest.approx(math.pi / 36)  # 5 degrees
    assert (band.min_angle, band.max_angle) == (pytest.approx(math.pi / 18), 50 * DEG)
    assert (high.min_angle, high.max_angle) == (None, pytest.approx(math.pi / 3))
    assert rotation.angle is None and rotation.tolerance == pytest.approx(math.pi / 20)
    np.testing.assert_allclose(rotation.rotation, [0.0, 0.0, math.pi / 4], atol=1e-15)
    assert (head.joint, head.bone, head.tolerance, head.line) == (
        None,
        "hand",
        0.03,
        line_of(POINTER, "bone: hand"),
    )
    np.testing.assert_array_equal(head.head, [0.5, 1.6, 0.0])
    assert (upper.bone, upper.tolerance, upper.angle, upper.rotation) == ("upper", 0.02, None, None)


def test_a_ball_root_has_a_joint() -> None:
    ball = rig_from_text(RIG.replace("name: arm\n", "name: arm\nroot: ball\n"), "ball.yaml")
    script = script_from_text("actions:\n  - expect: {joint: upper, angle: 10}\n", "s.yaml", ball)
    assert script.actions[0].joint == "upper"


def test_script_may_end_gripping(rig: RigSpec) -> None:
    script = script_from_text("actions:\n  - grip: hand\n", "s.yaml", rig)
    assert script.actions == (Grip("hand", None, 0.15, 2000, 40, 50, 2, 300, 30, False, 2),)


def pointer_bad(tmp_path: Path, rig: RigSpec, old: str, new: str) -> tuple[str, str]:
    return bad(tmp_path, rig, old, new, base=POINTER)


# Order of the pointer modes: one test per impossible sequence.


def test_grip_while_gripping(tmp_path: Path, rig: RigSpec) -> None:
    message, text = pointer_bad(tmp_path, rig, "  - release: {}\n", "")
    line = line_of(text, "nearest")
    expect(message, tmp_path, line, "actions[8].grip", "a release before gripping again")
    first = line_of(text, "grip: forearm")
    assert message.endswith(f"got a grip while gripping 'forearm' (gripped at line {first})")


def test_grip_while_gripping_nearest(tmp_path: Path, rig: RigSpec) -> None:
    message, text = pointer_bad(tmp_path, rig, "  - wait: 0.5\n", "  - grip: hand\n")
    expect(message, tmp_path, line_of(text, "grip: hand"), "actions[10].grip", "a release before")
    line = line_of(text, "nearest")
    assert f"got a grip while gripping the nearest bone (gripped at line {line})" in message


def test_release_while_free(tmp_path: Path, rig: RigSpec) -> None:
    message, text = pointer_bad(tmp_path, rig, "  - grip: forearm\n", "")
    expect(
        message,
        tmp_path,
        line_of(text, "release: {}"),
        "actions[7].release",
        "a grip before a release",
        "got a release while the pointer is free",
    )


def test_twist_while_free(tmp_path: Path, rig: RigSpec) -> None:
    after_release = "  - release:\n  - twist: {angle: 10, duration: 1}\n"
    message, text = pointer_bad(tmp_path, rig, "  - release:\n", after_release)
    expect(
        message,
        tmp_path,
        line_of(text, "angle: 10"),
        "actions[5].twist",
        "a grip before a twist",
        "got a twist while the pointer is free",
    )


def test_touch_while_gripping(tmp_path: Path, rig: RigSpec) -> None:
    message, text = pointer_bad(tmp_path, rig, "  - release:\n", "")
    expect(
        message,
        tmp_path,
        line_of(text, "touch"),
        "actions[4].touch",
        "a release before a touch",
        f"got a touch while gripping 'forearm' (gripped at line {line_of(text, '- grip:')})",
    )


# Names.


def test_unknown_pointer_action_suggests(tmp_path: Path, rig: RigSpec) -> None:
    message, text = pointer_bad(tmp_path, rig, "- twist:", "- twsit:")
    expect(
        message,
        tmp_path,
        line_of(text, "twsit"),
        "actions[3].twsit",
        "an action name (push, wait, key, grip, move, rotate, twist, release, touch, expect, "
        "pin, unpin)",
        "got 'twsit' (did you mean 'twist'?)",
    )


@pytest.mark.parametrize(
    ("old", "new", "path", "hint"),
    [
        ("grip: forearm", "grip: forarm", "actions[7].grip", "'forearm'?"),
        ("bone: forearm", "bone: forarm", "actions[0].grip.bone", "'forearm'?"),
        ("bone: hand,", "bone: hnad,", "actions[16].expect.bone", "'hand'?"),
        ("bone: upper,", "bone: uper,", "actions[17].expect.bone", "'upper'?"),
    ],
)
def test_unknown_bone_in_pointer_actions(
    tmp_path: Path, rig: RigSpec, old: str, new: str, path: str, hint: str
) -> None:
    message, text = pointer_bad(tmp_path, rig, old, new)
    got = new.split()[-1].rstrip(",")
    expect(
        message,
        tmp_path,
        line_of(text, new),
        path,
        "the name of a bone in the rig",
        f"got '{got}' (did you mean {hint})",
    )


def test_unknown_joint_suggests(tmp_path: Path, rig: RigSpec) -> None:
    message, text = pointer_bad(tmp_path, rig, "joint: hand, min", "joint: hnd, min")
    expect(
        message,
        tmp_path,
        line_of(text, "hnd"),
        "actions[12].expect.joint",
        "the name of a joint in the rig",
        "got 'hnd' (did you mean 'hand'?)",
    )


def test_fixed_root_has_no_joint(tmp_path: Path, rig: RigSpec) -> None:
    message, text = pointer_bad(tmp_path, rig, "joint: hand, max", "joint: upper, max")
    expect(
        message,
        tmp_path,
        line_of(text, "joint: upper"),
        "actions[15].expect.joint",
        "the name of a joint in the rig",
        "got 'upper' (the fixed root has no joint",
    )


# Durations, numbers and vectors.


@pytest.mark.parametrize(
    ("old", "new", "path", "got"),
    [
        ("duration: 1.5}", "duration: 0}", "actions[1].move.duration", "got 0"),
        ("duration: 0.5}", "duration: -0.5}", "actions[2].rotate.duration", "got -0.5"),
        ("duration: 2}", "duration: -2}", "actions[3].twist.duration", "got -2"),
        ("duration: 0.25}", "duration: 0.0}", "actions[5].touch.duration", "got 0.0"),
        ("duration: 1}", "duration: -1e-3}", "actions[6].move.duration", "got -1e-3"),
    ],
)
def test_pointer_durations_must_be_positive(
    tmp_path: Path, rig: RigSpec, old: str, new: str, path: str, got: str
) -> None:
    message, text = pointer_bad(tmp_path, rig, old, new)
    expect(message, tmp_path, line_of(text, new), path, "a positive finite number", got)


@pytest.mark.parametrize(
    ("old", "new", "path", "expected", "got"),
    [
        ("stiffness: 1500", "stiffness: 0", "stiffness", "a positive finite number", "got 0"),
        ("damping: 0", "damping: -1", "damping", "a non-negative finite number", "got -1"),
        ("rot_stiffness: 40", "rot_stiffness: -4", "rot_stiffness", "a positive", "got -4"),
        ("rot_damping: 1.5", "rot_damping: -.5", "rot_damping", "a non-negative", "got -.5"),
        ("force_limit: 200", "force_limit: 0", "force_limit", "a positive", "got 0"),
        ("torque_limit: 20", "torque_limit: .nan", "torque_limit", "a positive", "got .nan"),
        ("position_only: true", "position_only: 1", "position_only", "true or false", "got 1"),
    ],
)
def test_grip_gains_and_limits(
    tmp_path: Path, rig: RigSpec, old: str, new: str, path: str, expected: str, got: str
) -> None:
    message, text = pointer_bad(tmp_path, rig, old, new)
    expect(message, tmp_path, line_of(text, new), f"actions[0].grip.{path}", expected, got)


def test_grip_reach_must_be_positive(tmp_path: Path, rig: RigSpec) -> None:
    message, text = pointer_bad(tmp_path, rig, "reach: 0.1", "reach: 0")
    expect(message, tmp_path, line_of(text, "reach"), "actions[9].grip.reach", "positive", "got 0")


@pytest.mark.parametrize(
    ("old", "new", "path", "got"),
    [
        ("point: [0.2, 0, 0]", "point: [0.2, 0]", "actions[0].grip.point", "a list of 2 items"),
        ("to: [0.4, 1.2, 0]", "to: 0.4", "actions[1].move.to", "got 0.4"),
        ("axis: [0, 3, 4]", "axis: [0, y, 4]", "actions[2].rotate.axis[1]", "got 'y'"),
        ("by: [0, -0.1, 0]", "by: {y: -0.1}", "actions[5].touch.by", "got a mapping"),
        ("rotation: [0, 0, 45]", "rotation: [45]", "actions[14].expect.rotation", "1 item"),
        ("head: [0.5, 1.6, 0.0]", "head: [.inf, 1, 0]", "actions[16].expect.head[0]", ".inf"),
        ("start: [0.1, 1.1, 0.2]", "start: [0.1, 1.1]", "pointer.start", "a list of 2 items"),
        ("offset: [0, 1, 0.5]", "offset: []", "workspace.offset", "got an empty list"),
    ],
)
def test_malformed_pointer_vectors(
    tmp_path: Path, rig: RigSpec, old: str, new: str, path: str, got: str
) -> None:
    message, text = pointer_bad(tmp_path, rig, old, new)
    expect(message, tmp_path, line_of(text, new), path, got)
    assert "expected a list of 3 numbers" in message or "expected a finite number" in message


def test_zero_rotation_axis(tmp_path: Path, rig: RigSpec) -> None:
    message, text = pointer_bad(tmp_path, rig, "axis: [0, 3, 4]", "axis: [0, 0, 0.0]")
    expect(
        message,
        tmp_path,
        line_of(text, "axis"),
        "actions[2].rotate.axis",
        "a non-zero rotation axis, got [0, 0, 0]",
    )


@pytest.mark.parametrize(
    ("old", "new", "path", "expected", "got"),
    [
        ("radius: 0.03", "radius: 0", "pointer.radius", "a positive finite number", "got 0"),
        ("scale: 2.5", "scale: -2.5", "workspace.scale", "a positive finite number", "-2.5"),
        ("max_force: 15", "max_force: 0", "haptics.max_force", "a positive", "got 0"),
        ("max_torque: 0.5", "max_torque: no", "haptics.max_torque", "a positive", "boolean"),
        ("lowpass: 0.25", "lowpass: 1", "haptics.lowpass", "a number in [0, 1)", "got 1"),
        ("lowpass: 0.25", "lowpass: -0.1", "haptics.lowpass", "a number in [0, 1]", "-0.1"),
    ],
)
def test_pointer_settings_ranges(
    tmp_path: Path, rig: RigSpec, old: str, new: str, path: str, expected: str, got: str
) -> None:
    message, text = pointer_bad(tmp_path, rig, old, new)
    expect(message, tmp_path, line_of(text, new), path, expected, got)


@pytest.mark.parametrize(
    ("old", "new", "path", "expected", "got"),
    [
        ("angle: 30,", "angle: 181,", "actions[11].expect.angle", "a number in [0, 180]", "181"),
        ("min_angle: 20", "min_angle: -20", "actions[12].expect.min_angle", "[0, 180]", "-20"),
        ("tolerance: 4", "tolerance: 0", "actions[11].expect.tolerance", "a positive", "got 0"),
        ("tolerance: 0.03", "tolerance: -1", "actions[16].expect.tolerance", "positive", "-1"),
        (
            "[0, 0, 45]",
            "[0, 200, 45]",
            "actions[14].expect.rotation",
            "a rotation vector of at most 180 degrees",
            "got 205 degrees",
        ),
        (
            "max_angle: 50",
            "max_angle: 5",
            "actions[13].expect.max_angle",
            "max_angle >= min_angle",
            "got min_angle 10 > max_angle 5",
        ),
    ],
)
def test_expect_values(
    tmp_path: Path, rig: RigSpec, old: str, new: str, path: str, expected: str, got: str
) -> None:
    message, text = pointer_bad(tmp_path, rig, old, new)
    expect(message, tmp_path, line_of(text, new), path, expected, got)


# Keys: unknown, excluding each other, missing.


@pytest.mark.parametrize(
    ("old", "new", "path", "hint"),
    [
        ("stiffness: 1500", "stifness: 1500", "actions[0].grip.stifness", "'stiffness'?"),
        ("{to: [0.4", "{too: [0.4", "actions[1].move.too", "'to'?"),
        ("{axis:", "{axes:", "actions[2].rotate.axes", "'axis'?"),
        ("{angle: -45", "{angel: -45", "actions[3].twist.angel", "'angle'?"),
        ("{by: [0, -0.1", "{bye: [0, -0.1", "actions[5].touch.bye", "'by'?"),
        ("tolerance: 4}", "tolerence: 4}", "actions[11].expect.tolerence", "'tolerance'?"),
        ("radius: 0.03", "radios: 0.03", "pointer.radios", "'radius'?"),
        ("scale: 2.5", "scal: 2.5", "workspace.scal", "'scale'?"),
        ("lowpass: 0.25", "low_pass: 0.25", "haptics.low_pass", "'lowpass'?"),
    ],
)
def test_unknown_keys_in_pointer_parts(
    tmp_path: Path, rig: RigSpec, old: str, new: str, path: str, hint: str
) -> None:
    message, text = pointer_bad(tmp_path, rig, old, new)
    expect(message, tmp_path, line_of(text, new), path, "one of the keys", f"(did you mean {hint})")


def test_release_takes_no_value(tmp_path: Path, rig: RigSpec) -> None:
    message, text = pointer_bad(tmp_path, rig, "release: {}", "release: now")
    expect(
        message,
        tmp_path,
        line_of(text, "release: now"),
        "actions[8].release",
        "nothing after 'release:' (or an empty mapping {})",
        "got 'now'",
    )


@pytest.mark.parametrize(
    ("old", "new", "path", "expected", "got"),
    [
        (
            "{to: [0.4, 1.2, 0],",
            "{to: [0.4, 1.2, 0], by: [0, 0, 0],",
            "actions[1].move.by",
            "either 'to' or 'by'",
            "got both",
        ),
        ("{to: [0.4, 1.2, 0],", "{", "actions[1].move", "a 'to' or a 'by'", "got neither"),
        ("{by: [0, -0.1, 0],", "{", "actions[5].touch", "a 'to' or a 'by'", "got neither"),
        ("{axis: [0, 3, 4], ", "{", "actions[2].rotate", "a value for 'axis'", "no 'axis' key"),
        ("{angle: -45, ", "{", "actions[3].twist", "a value for 'angle'", "no 'angle' key"),
        (
            "{nearest: true,",
            "{bone: hand, nearest: true,",
            "actions[9].grip.nearest",
            "either 'bone' or 'nearest'",
            "got both",
        ),
        (
            "{nearest: true, reach: 0.1}",
            "{stiffness: 10}",
            "actions[9].grip",
            "a 'bone' or 'nearest: true'",
            "got neither",
        ),
        ("nearest: true", "nearest: false", "actions[9].grip.nearest", "true", "boolean false"),
        (
            "{nearest: true, reach",
            "{bone: hand, reach",
            "actions[9].grip.reach",
            "'reach' only with 'nearest: true'",
            "got it with a named 'bone'",
        ),
        (
            "{nearest: true,",
            "{nearest: true, point: [0, 0, 0],",
            "actions[9].grip.point",
            "'point' only with a named 'bone'",
            "got it with 'nearest: true'",
        ),
        (
            "{joint: forearm, angle: 30,",
            "{joint: forearm, bone: hand, angle: 30,",
            "actions[11].expect.bone",
            "either 'joint' or 'bone'",
            "got both",
        ),
        (
            "{joint: forearm, angle: 30,",
            "{angle: 30,",
            "actions[11].expect",
            "a 'joint' or a 'bone'",
            "got neither",
        ),
        (
            "{joint: forearm, angle: 30, tolerance: 4}",
            "{joint: forearm, tolerance: 4}",
            "actions[11].expect",
            "one of 'angle', 'rotation', 'min_angle', 'max_angle'",
            "got none of them",
        ),
        (
            "{joint: forearm, angle: 30,",
            "{joint: forearm, angle: 30, max_angle: 40,",
            "actions[11].expect.max_angle",
            "one of 'angle', 'rotation' or 'min_angle'/'max_angle'",
            "got both 'angle' and 'max_angle'",
        ),
        (
            "{joint: hand, min_angle: 20}",
            "{joint: hand, min_angle: 20, tolerance: 3}",
            "actions[12].expect.tolerance",
            "'tolerance' only with 'angle' or 'rotation'",
            "got it with min_angle/max_angle",
        ),
        (
            "head: [0.5, 1.6, 0.0], ",
            "",
            "actions[16].expect",
            "a 'head' position to check for the 'bone'",
            "got no 'head' key",
        ),
        (
            "{joint: hand, min_angle: 20}",
            "{joint: hand, min_angle: 20, head: [0, 0, 0]}",
            "actions[12].expect.head",
            "'head' only with a 'bone'",
            "got it with a 'joint'",
        ),
        (
            "{bone: upper, head",
            "{bone: upper, angle: 3, head",
            "actions[17].expect.angle",
            "'angle' only with a 'joint'",
            "got it with a 'bone'",
        ),
    ],
)
def test_keys_that_exclude_or_need_each_other(
    tmp_path: Path, rig: RigSpec, old: str, new: str, path: str, expected: str, got: str
) -> None:
    message, _ = pointer_bad(tmp_path, rig, old, new)
    expect(message, tmp_path, line_of(POINTER, old), path, expected, got)  # no line moves
