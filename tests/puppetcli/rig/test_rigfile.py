"""Rig files: a valid rig converts exactly; every class of bad input gives one precise line."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

from puppetcli.errors import RigError
from puppetcli.rig.load import load_rig, rig_from_text
from solver.model import build_model

DOCS = Path(__file__).resolve().parents[3] / "docs"

VALID = """\
name: doll
ground: {height: -0.5, friction: 0.9}
solver: {h: 0.01, method: pgs, iterations: 30, warm_start: false, warm_start_factor: 0.7}
defaults:
  shape: {type: capsule, radius: 0.04}
  density: 1e3
  joint: {kf: 50.0, df: 2.0, dd: 100.0, yield: 5.0, swing: 120, twist: [-60, 45]}
bones:
  - name: hand
    parent: forearm
    head: [0.5, 1.0, 0]
    tail: [0.5, 1.0, 0]
    shape: {type: sphere}
    joint: {plastic: false, yield: null}
  - name: forearm
    parent: upper
    head: [0.3, 1.0, 0]
    tail: [0.5, 1.0, 0]
    density: 1100
    joint: {kf: [1, 2, 3], twist: ~}
  - name: upper
    head: [0, 1.0, 0]
    tail: [0.3, 1.0, 0]
    shape: {type: box, size: [0.3, 0.1, 0.2]}
    inertia: [2.0, 3.0, 4.0, 0.1, 0.2, 0.3]
  - name: tail
    parent: upper
    head: [0, 1.0, 0]
    tail: [0, 0.5, 0]
    shape: {}
    mass: 2.5
    com: [0, 0.8, 0]
    collide: false
props:
  - name: table
    shape: {type: box, size: [1.0, 0.05, 0.6]}
    position: [0.5, 0.8, 0]
    rotation: {axis: [0, 2, 0], angle: 90}
  - name: ball
    shape: {type: sphere, radius: 0.1}
    rotation: [2, 0, 0, 0]
    dynamic: true
    density: 500
"""


def write(tmp_path: Path, text: str, name: str = "doll.yaml") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def rig_error(tmp_path: Path, text: str) -> str:
    """The RigError message for ``text`` saved as doll.yaml."""
    with pytest.raises(RigError) as info:
        load_rig(write(tmp_path, text))
    message = str(info.value)
    assert "\n" not in message
    return message


def line_of(text: str, marker: str, nth: int = 1) -> int:
    """1-based line of the ``nth`` line containing ``marker`` (independent of the loader)."""
    hits = [i + 1 for i, line in enumerate(text.splitlines()) if marker in line]
    return hits[nth - 1]


def expect(message: str, tmp_path: Path, line: int, path: str, *words: str) -> None:
    assert message.startswith(f"{tmp_path / 'doll.yaml'}:{line}: {path}: expected "), message
    for word in words:
        assert word in message, message


def test_valid_rig_converts_units_order_and_defaults(tmp_path: Path) -> None:
    rig = load_rig(write(tmp_path, VALID))
    assert [b.name for b in rig.bones] == ["upper", "forearm", "hand", "tail"]
    upper, forearm, hand, tail = rig.bones
    assert upper.parent is None and forearm.parent == "upper" and hand.parent == "forearm"
    assert upper.shape.kind == "box" and upper.shape.half_extents == (0.15, 0.05, 0.1)
    assert upper.mass == pytest.approx(1000.0 * 0.3 * 0.1 * 0.2)
    assert upper.rheology is None  # fixed root
    np.testing.assert_allclose(upper.inertia, [[2.0, 0.1, 0.2], [0.1, 3.0, 0.3], [0.2, 0.3, 4.0]])
    r, length = 0.04, 0.2
    assert forearm.shape.kind == "capsule" and forearm.shape.radius == 0.04
    assert forearm.mass == pytest.approx(
        1100.0 * (math.pi * r * r * length + 4 / 3 * math.pi * r**3)
    )
    np.testing.assert_array_equal(forearm.rheology.kf, [1.0, 2.0, 3.0])
    np.testing.assert_array_equal(forearm.rheology.df, [2.0, 2.0, 2.0])
    np.testing.assert_array_equal(forearm.rheology.dd, [100.0, 100.0, 100.0])
    assert forearm.rheology.yield_torque == 5.0
    assert forearm.limits.swing == pytest.approx(2.0 * math.pi / 3.0)
    assert forearm.limits.twist == (-math.inf, math.inf)
    assert hand.shape.kind == "sphere" and hand.shape.radius == 0.04
    assert hand.mass == pytest.approx(1000.0 * 4.0 / 3.0 * math.pi * 0.04**3)
    assert np.all(np.isinf(hand.rheology.dd)) and hand.rheology.yield_torque == math.inf
    assert hand.limits.twist == pytest.approx((-math.pi / 3.0, math.pi / 4.0))
    assert tail.shape == tail.shape.__class__("capsule", radius=0.04) and tail.mass == 2.5
    np.testing.assert_array_equal(tail.com, [0.0, 0.8, 0.0])
    assert not tail.collide and hand.collide


def test_valid_rig_top_level_and_props(tmp_path: Path) -> None:
    rig = load_rig(write(tmp_path, VALID))
    assert rig.name == "doll" and rig.root_mode == "fixed" and rig.bone_friction == 0.6
    np.testing.assert_array_equal(rig.gravity, [0.0, -9.81, 0.0])
    assert (rig.ground.height, rig.ground.friction) == (-0.5, 0.9)
    assert rig.solver.h == 0.01 and rig.solver.method == "pgs" and rig.solver.iterations == 30
    assert rig.solver.warm_start is False and rig.solver.warm_start_factor == 0.7
    table, ball = rig.props
    assert table.shape.half_extents == (0.5, 0.025, 0.3) and not table.dynamic
    half = math.radians(45.0)
    np.testing.assert_allclose(table.rotation, [math.cos(half), 0.0, math.sin(half), 0.0])
    np.testing.assert_array_equal(ball.rotation, [1.0, 0.0, 0.0, 0.0])
    assert ball.dynamic and ball.mass == pytest.approx(500.0 * 4.0 / 3.0 * math.pi * 0.1**3)


def test_ball_root_keeps_its_joint_and_defaults_give_capsule_radius(tmp_path: Path) -> None:
    text = "name: a\nroot: ball\nbones:\n  - {name: r, head: [0, 0, 0], tail: [0, 2, 0],"
    text += " joint: {kf: 3, swing: 90, plastic: false}}\n"
    (bone,) = load_rig(write(tmp_path, text)).bones
    assert bone.shape.radius == pytest.approx(0.2)  # 0.1 × length without a default radius
    np.testing.assert_array_equal(bone.rheology.kf, [3.0, 3.0, 3.0])
    assert np.all(np.isinf(bone.rheology.dd)) and bone.limits.swing == pytest.approx(math.pi / 2)


def test_documented_example_loads() -> None:
    doc = (DOCS / "rig-format.md").read_text(encoding="utf-8")
    example = re.search(r"```yaml\n(.*?)```", doc, re.S).group(1)
    rig = rig_from_text(example, "rig-format.md")
    names = [b.name for b in rig.bones]
    assert names.index("upper_arm") < names.index("forearm") < names.index("hand")
    assert len(rig.props) == 2


def bad(tmp_path: Path, old: str, new: str) -> tuple[str, str]:
    """VALID with one substitution: (error message, new text)."""
    assert old in VALID
    text = VALID.replace(old, new, 1)
    return rig_error(tmp_path, text), text


def test_a_free_axis_of_a_sprung_joint_names_the_bone(tmp_path: Path) -> None:
    # kf and df both 0 about y while x and z have a spring: the row would divide by 0
    message, text = bad(tmp_path, "{kf: [1, 2, 3], twist: ~}", "{kf: [1, 0, 3], df: [2, 0, 2]}")
    expect(message, tmp_path, line_of(text, "df: [2, 0, 2]"), "bones[1].joint",
           "kf [1, 0, 3] and df [2, 0, 2]")  # fmt: skip


def test_unknown_top_level_key_suggests(tmp_path: Path) -> None:
    message, text = bad(tmp_path, "ground:", "grund:")
    expect(message, tmp_path, line_of(text, "grund"), "grund", "got 'grund'", "'ground'?")


def test_unknown_nested_key_suggests(tmp_path: Path) -> None:
    message, text = bad(tmp_path, "{kf: [1, 2, 3]", "{kff: [1, 2, 3]")
    expect(message, tmp_path, line_of(text, "kff"), "bones[1].joint.kff", "(did you mean 'kf'?)")


def test_missing_required_key(tmp_path: Path) -> None:
    message, text = bad(tmp_path, "    tail: [0.3, 1.0, 0]\n", "")
    expect(message, tmp_path, line_of(text, "name: upper"), "bones[2]", "'tail'", "no 'tail' key")


def test_key_given_twice(tmp_path: Path) -> None:
    message, text = bad(tmp_path, "    mass: 2.5\n", "    mass: 2.5\n    mass: 3\n")
    expect(message, tmp_path, line_of(text, "mass: 3"), "bones[3].mass", "each key once", "again")


def test_unknown_parent_suggests(tmp_path: Path) -> None:
    message, text = bad(tmp_path, "parent: forearm", "parent: forarm")
    expect(
        message, tmp_path, line_of(text, "forarm"), "bones[0].parent", "got 'forarm'", "'forearm'?"
    )


def test_second_root_names_both(tmp_path: Path) -> None:
    message, text = bad(
        tmp_path, "    parent: upper\n    head: [0, 1.0, 0]\n", "    head: [0, 1.0, 0]\n"
    )
    expect(message, tmp_path, line_of(text, "name: tail"), "bones[3]", "'tail'", "'upper'", "root")


def test_parent_cycle_names_its_bones(tmp_path: Path) -> None:
    message, text = bad(tmp_path, "parent: upper\n    head: [0.3", "parent: hand\n    head: [0.3")
    expect(message, tmp_path, line_of(text, "parent: forearm"), "bones[0].parent", "cycle")
    assert "hand -> forearm -> hand" in message


def test_duplicate_bone_name(tmp_path: Path) -> None:
    message, text = bad(tmp_path, "name: tail", "name: hand")
    expect(message, tmp_path, line_of(text, "name: hand", 2), "bones[3].name", "unique", "'hand'")
    assert f"first at line {line_of(text, 'name: hand')}" in message


def test_prop_named_like_a_bone(tmp_path: Path) -> None:
    message, text = bad(tmp_path, "name: table", "name: forearm")
    expect(
        message, tmp_path, line_of(text, "name: forearm", 2), "props[0].name", "'forearm'", "bone"
    )


@pytest.mark.parametrize(
    ("old", "new", "path"),
    [
        ("size: [0.3, 0.1, 0.2]", "size: [0.3, 0, 0.2]", "bones[2].shape.size[1]"),
        ("{type: sphere}", "{type: sphere, radius: -0.1}", "bones[0].shape.radius"),
        ("mass: 2.5", "mass: 0", "bones[3].mass"),
        ("density: 1100", "density: -5", "bones[1].density"),
        ("density: 500", "density: 0.0", "props[1].density"),
    ],
)
def test_non_positive_sizes_radii_masses_densities(
    tmp_path: Path, old: str, new: str, path: str
) -> None:
    message, text = bad(tmp_path, old, new)
    expect(message, tmp_path, line_of(text, new), path, "a positive finite number")


@pytest.mark.parametrize(
    ("new", "got"),
    [("[2.0, 3.0, 6.0]", "principal moments"), ("[2.0, 3.0, 4.0, 5.0, 0, 0]", "principal moments")],
)
def test_bad_inertia(tmp_path: Path, new: str, got: str) -> None:
    message, text = bad(tmp_path, "inertia: [2.0, 3.0, 4.0, 0.1, 0.2, 0.3]", f"inertia: {new}")
    expect(
        message, tmp_path, line_of(text, "inertia"), "bones[2].inertia", "positive-definite", got
    )


@pytest.mark.parametrize(
    ("old", "new", "path", "expected"),
    [
        (
            "kf: 50.0",
            "kf: -1",
            "defaults.joint.kf",
            "expected a non-negative finite number, got -1",
        ),
        ("df: 2.0", "df: .nan", "defaults.joint.df", "got .nan"),
        (
            "dd: 100.0",
            "dd: .inf",
            "defaults.joint.dd",
            "expected a positive finite number, got .inf",
        ),
        ("yield: 5.0", "yield: on", "defaults.joint.yield", "got boolean true"),
        # a coefficient between 0 and 1e-9: kf·h + df would underflow to 0 (a NaN at step 0)
        ("kf: 50.0", "kf: 1.0e-308", "defaults.joint.kf", "0 or at least 1e-09, got 1.0e-308"),
    ],
)
def test_negative_or_non_finite_coefficients(
    tmp_path: Path, old: str, new: str, path: str, expected: str
) -> None:
    message, text = bad(tmp_path, old, new)
    expect(message, tmp_path, line_of(text, new), path, expected)


@pytest.mark.parametrize(
    ("new", "path", "expected"),
    [
        (
            "head: [0.3, 1.0]",
            "bones[1].head",
            "expected a list of 3 numbers, got a list of 2 items",
        ),
        ("head: [0.3, x, 0]", "bones[1].head[1]", "expected a finite number, got 'x'"),
        ("head: 0.3", "bones[1].head", "expected a list of 3 numbers, got 0.3"),
    ],
)
def test_malformed_vectors(tmp_path: Path, new: str, path: str, expected: str) -> None:
    message, text = bad(tmp_path, "head: [0.3, 1.0, 0]", new)
    expect(message, tmp_path, line_of(text, new), path, expected)


@pytest.mark.parametrize("shape", ["{type: capsule}", "{type: box, size: [1, 1, 1]}"])
def test_zero_length_capsule_or_box(tmp_path: Path, shape: str) -> None:
    message, text = bad(tmp_path, "{type: sphere}", shape)
    expect(
        message, tmp_path, line_of(text, "tail: [0.5, 1.0, 0]"), "bones[0].tail", "needs a sphere"
    )


def test_yaml_syntax_error_has_line(tmp_path: Path) -> None:
    text = VALID.replace("position: [0.5, 0.8, 0]", "position: [0.5, 0.8, 0")
    message = rig_error(tmp_path, text)
    assert message.startswith(f"{tmp_path / 'doll.yaml'}:{line_of(text, 'rotation: {axis')}: ")
    assert "YAML syntax error: expected ',' or ']'" in message


@pytest.mark.parametrize(
    ("old", "new", "path", "hint"),
    [
        ("{type: sphere}", "{type: sphear}", "bones[0].shape.type", "'sphere'?"),
        ("name: doll\n", "name: doll\nroot: fixd\n", "root", "'fixed'?"),
        ("method: pgs", "method: pgss", "solver.method", "'pgs'?"),
    ],
)
def test_unknown_choice_suggests(tmp_path: Path, old: str, new: str, path: str, hint: str) -> None:
    message, text = bad(tmp_path, old, new)
    marker = new.splitlines()[-1].split(": ")[-1]
    expect(message, tmp_path, line_of(text, marker), path, "expected one of", hint)


@pytest.mark.parametrize("twist", ["[10, 60]", "[-60, -10]", "[-200, 30]"])
def test_twist_range_must_contain_zero(tmp_path: Path, twist: str) -> None:
    message, text = bad(tmp_path, "twist: [-60, 45]", f"twist: {twist}")
    path = "defaults.joint.twist" + ("[0]" if "200" in twist else "")
    expect(message, tmp_path, line_of(text, "twist"), path)
    assert ("lo <= 0 <= hi" in message) or ("[-180, 180]" in message)


@pytest.mark.parametrize("swing", ["0", "200"])
def test_swing_out_of_range(tmp_path: Path, swing: str) -> None:
    message, text = bad(tmp_path, "swing: 120", f"swing: {swing}")
    expect(message, tmp_path, line_of(text, "swing"), "defaults.joint.swing", "(0, 180]", swing)


@pytest.mark.parametrize(
    ("gravity", "expected"), [("[0, -9.81]", "a list of 2 items"), ("down", "got 'down'")]
)
def test_malformed_gravity(tmp_path: Path, gravity: str, expected: str) -> None:
    message, _ = bad(tmp_path, "name: doll\n", f"name: doll\ngravity: {gravity}\n")
    expect(message, tmp_path, 2, "gravity", "a list of 3 numbers", expected)


def test_yaml_boolean_as_name(tmp_path: Path) -> None:
    message, text = bad(tmp_path, "name: tail", "name: yes")
    expect(message, tmp_path, line_of(text, "name: yes"), "bones[3].name", "got boolean true")


def test_mass_and_density_together(tmp_path: Path) -> None:
    message, text = bad(tmp_path, "    mass: 2.5\n", "    mass: 2.5\n    density: 900\n")
    expect(message, tmp_path, line_of(text, "density: 900"), "bones[3].density", "either", "both")


def test_joint_on_fixed_root(tmp_path: Path) -> None:
    message, text = bad(tmp_path, "    inertia:", "    joint: {kf: 1}\n    inertia:")
    expect(message, tmp_path, line_of(text, "joint: {kf: 1}"), "bones[2].joint", "root: ball")


def test_shape_key_of_another_type(tmp_path: Path) -> None:
    message, text = bad(tmp_path, "{type: sphere}", "{type: sphere, size: [1, 1, 1]}")
    expect(
        message, tmp_path, line_of(text, "size: [1, 1, 1]"), "bones[0].shape.size", "for a sphere"
    )


def test_bad_solver_numbers(tmp_path: Path) -> None:
    message, _ = bad(tmp_path, "iterations: 30", "iterations: 0")
    expect(message, tmp_path, 3, "solver.iterations", "a positive integer, got 0")
    message, _ = bad(tmp_path, "warm_start_factor: 0.7", "warm_start_factor: 1.5")
    expect(message, tmp_path, 3, "solver.warm_start_factor", "in [0, 1], got 1.5")
    message, _ = bad(tmp_path, "warm_start_factor: 0.7", "contact_slop: 0.05")
    expect(message, tmp_path, 3, "solver.contact_slop", "in [0, 0.01], got 0.05")


def test_the_contact_slop_reaches_the_model(tmp_path: Path) -> None:
    default = load_rig(write(tmp_path, VALID))
    assert default.solver.contact_slop == build_model(default).options.contact_slop == 0.0005
    given = load_rig(write(tmp_path, VALID.replace("warm_start_factor: 0.7", "contact_slop: 0")))
    assert given.solver.contact_slop == build_model(given).options.contact_slop == 0.0


def test_zero_quaternion(tmp_path: Path) -> None:
    message, text = bad(tmp_path, "rotation: [2, 0, 0, 0]", "rotation: [0, 0, 0, 0]")
    expect(message, tmp_path, line_of(text, "rotation: [0"), "props[1].rotation", "non-zero")


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("", "expected a YAML mapping, got an empty document"),
        ("- a\n- b\n", "got a list of 2 items"),
    ],
)
def test_empty_file_or_top_level_not_a_mapping(tmp_path: Path, text: str, expected: str) -> None:
    message = rig_error(tmp_path, text)
    assert message.startswith(f"{tmp_path / 'doll.yaml'}:1: ") and expected in message


def test_empty_bone_list(tmp_path: Path) -> None:
    message = rig_error(tmp_path, "name: a\nbones: []\n")
    expect(message, tmp_path, 2, "bones", "a non-empty list of bones, got an empty list")


def test_missing_file_is_a_rig_error(tmp_path: Path) -> None:
    with pytest.raises(RigError, match=r"nothing\.yaml: cannot read"):
        load_rig(tmp_path / "nothing.yaml")
