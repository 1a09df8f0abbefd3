"""Script ``pin``/``unpin`` actions: what they convert to, and one precise line for every bad
input (through the CLI: exit 1, no traceback, nothing written)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from puppetcli.cli import cli
from puppetcli.errors import ScriptError
from puppetcli.rig.load import rig_from_text
from puppetcli.script.load import script_from_text
from puppetcli.script.pins import Pin, Unpin

RIG = """\
name: arm
bones:
  - {name: upper, head: [0, 1, 0], tail: [0.3, 1, 0], shape: {type: capsule, radius: 0.04}}
  - {name: forearm, parent: upper, head: [0.3, 1, 0], tail: [0.5, 1, 0],
     shape: {type: capsule, radius: 0.04}}
  - {name: hand, parent: forearm, head: [0.5, 1, 0], tail: [0.6, 1, 0],
     shape: {type: box, size: [0.04, 0.1, 0.02]}}
"""
PINS = """\
actions:
  - pin: upper
  - pin: {bone: hand, point: [0.09, 0.015, 0.005], orient: true, force_limit: 40,
          torque_limit: 2.5}
  - unpin: upper
  - pin: {bone: upper, point: [0.3, 0.04, 0]}
  - unpin: all
"""


@pytest.fixture(scope="module")
def rig():
    return rig_from_text(RIG, "arm.yaml")


def test_pins_convert(rig) -> None:
    pin, hand, unpin, edge, everything = script_from_text(PINS, "p.yaml", rig).actions
    assert pin == Pin("upper", None, False, np.inf, np.inf, 2)
    assert (hand.bone, hand.orient, hand.force_limit, hand.torque_limit, hand.line) == (
        "hand", True, 40.0, 2.5, 3,
    )  # fmt: skip
    # the box (size across, along, across the bone) spans x 0 … 0.1, y ±0.02, z ±0.01
    np.testing.assert_array_equal(hand.point, [0.09, 0.015, 0.005])
    assert unpin == Unpin("upper", 5)
    np.testing.assert_array_equal(edge.point, [0.3, 0.04, 0.0])  # on the capsule's rim
    assert everything == Unpin(None, 7)


# (action lines after ``- pin: upper``, path, words of the one line)
BAD = [
    ("  - pin: elbow\n", "actions[1].pin", ("the name of a bone in the rig", "'elbow'")),
    # capsule r = 0.04: 0.05 above the axis is 0.01 m outside
    (
        "  - pin: {bone: forearm, point: [0.1, 0.05, 0]}\n",
        "actions[1].pin.point",
        ("inside the bone's capsule", "0.01 m outside"),
    ),
    # the box reaches 0.02 m above the bone's axis: 0.03 is 0.01 m outside
    (
        "  - pin: {bone: hand, point: [0.05, 0.03, 0]}\n",
        "actions[1].pin.point",
        ("inside the bone's box", "0.01 m outside"),
    ),
    (
        "  - pin: {bone: hand, force_limit: .inf}\n",
        "actions[1].pin.force_limit",
        ("a positive finite number", ".inf"),
    ),
    (
        "  - pin: {bone: hand, torque_limit: .nan}\n",
        "actions[1].pin.torque_limit",
        ("a positive finite number",),
    ),
    ("  - pin: {bone: hand, force_limit: 0}\n", "actions[1].pin.force_limit", ("positive",)),
    ("  - unpin: hand\n", "actions[1].unpin", ("a pinned bone", "'hand', not pinned", "'upper'")),
    ("  - pin: upper\n", "actions[1].pin", ("an unpin before pinning 'upper' again", "line 2")),
    ("  - unpin: all\n  - unpin: all\n", "actions[2].unpin", ("'all' with no bone pinned",)),
    ("  - pin: {bone: hand, orient: 1}\n", "actions[1].pin.orient", ("true or false",)),
]


@pytest.mark.parametrize(("lines", "path", "words"), BAD, ids=[b[1] + str(i) for i, b in
                                                                 enumerate(BAD)])  # fmt: skip
def test_bad_pins_fail_on_their_line(tmp_path: Path, lines: str, path: str, words: tuple) -> None:
    rig_path = tmp_path / "arm.yaml"
    rig_path.write_text(RIG)
    script = tmp_path / "bad.yaml"
    script.write_text("actions:\n  - pin: upper\n" + lines)
    out = tmp_path / "out"
    result = CliRunner().invoke(cli, ["pose", str(rig_path), str(script), "-o", str(out)])
    assert result.exit_code == 1, result.output
    assert isinstance(result.exception, SystemExit)
    assert "Traceback" not in result.output
    (line,) = result.stderr.splitlines()
    row = 3 + lines[: lines.rfind("  - ")].count("\n")
    assert line.startswith(f"error: {script}:{row}: {path}: expected "), line
    for word in words:
        assert word in line, line
    assert not out.exists() or not any(out.iterdir())  # nothing written


def test_a_point_on_the_surface_is_inside_and_just_beyond_is_not(rig) -> None:
    on = "actions:\n  - pin: {bone: upper, point: [0.15, 0.04, 0]}\n"
    assert script_from_text(on, "p.yaml", rig).actions[0].point[1] == 0.04
    with pytest.raises(ScriptError, match="outside it"):
        script_from_text(on.replace("0.04", "0.0401"), "p.yaml", rig)
