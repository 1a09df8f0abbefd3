"""keyframes.json: exact round trip, key replacement, one-line errors for bad files."""

from __future__ import annotations

import copy
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from puppetcli.errors import PuppetError
from puppetcli.run.keyframes import (
    BonePose,
    Keyframe,
    KeyframesError,
    KeyframeSet,
    read_keyframes,
    write_keyframes,
)

BONES = ("hips", "spine", "l.arm")


def unit_quat(rng: np.random.Generator) -> np.ndarray:
    q = rng.standard_normal(4)
    return q / np.linalg.norm(q)


def make_key(rng: np.random.Generator, time: float, label: str = "key", **extra: Any) -> Keyframe:
    """A key with random, full-precision poses for every bone."""
    bones = {
        name: BonePose(head=rng.standard_normal(3), rotation=unit_quat(rng), local=unit_quat(rng))
        for name in BONES
    }
    return Keyframe(time=time, label=label, bones=bones, extra=dict(extra))


def test_round_trip_is_exact(tmp_path: Path) -> None:
    rng = np.random.default_rng(1)
    keys = KeyframeSet(
        [
            make_key(rng, 0.1 + 0.2, "grab", line=12, peak_force=3.141592653589793),
            make_key(rng, 1 / 3, "release", notes={"who": "test", "ids": [1, 2]}),
            make_key(rng, 2.0, "rest"),
        ]
    )
    path = tmp_path / "keyframes.json"
    write_keyframes(path, "doll", keys)
    rig, back = read_keyframes(path)
    assert rig == "doll"
    assert back == list(keys)  # BonePose compares arrays exactly
    assert back[0].time == 0.1 + 0.2 and back[0].extra == {"line": 12, "peak_force": np.pi}


def test_file_layout_is_the_documented_contract(tmp_path: Path) -> None:
    """Strict JSON (no NaN tokens) with the field order time, label, extras, bones."""
    rng = np.random.default_rng(2)
    path = tmp_path / "keyframes.json"
    write_keyframes(path, "doll", [make_key(rng, 0.5, "a", line=3)])

    def no_constants(token: str) -> None:
        raise AssertionError(f"non-standard JSON token {token}")

    doc = json.loads(path.read_text(), parse_constant=no_constants)
    assert list(doc) == ["rig", "keys"]
    key = doc["keys"][0]
    assert list(key) == ["time", "label", "line", "bones"]
    assert list(key["bones"]) == list(BONES)
    assert list(key["bones"]["hips"]) == ["head", "rotation", "local"]
    assert [len(v) for v in key["bones"]["hips"].values()] == [3, 4, 4]


def test_add_replaces_same_time_and_keeps_order() -> None:
    rng = np.random.default_rng(3)
    keys = KeyframeSet()
    for t in (0.3, 0.1, 0.2):
        keys.add(make_key(rng, t, f"k{t}"))
    keys.add(make_key(rng, 0.2 + 5e-10, "replaced"))
    keys.add(make_key(rng, 0.1 - 5e-10, "replaced too"))
    keys.add(make_key(rng, 0.3 + 2e-9, "distinct"))
    assert [k.label for k in keys] == ["replaced too", "replaced", "k0.3", "distinct"]
    times = [k.time for k in keys]
    assert times == sorted(times) and len(keys) == 4


def test_add_rejects_nan_time() -> None:
    with pytest.raises(ValueError, match="finite"):
        KeyframeSet().add(make_key(np.random.default_rng(0), float("nan")))


def test_bone_pose_copies_and_checks_shapes() -> None:
    head = np.zeros(3)
    pose = BonePose(head=head, rotation=[1, 0, 0, 0], local=[1, 0, 0, 0])
    head[0] = 5.0
    assert pose.head[0] == 0.0  # a kept key does not move with the live state
    with pytest.raises(ValueError, match=r"rotation has shape \(3,\)"):
        BonePose(head=np.zeros(3), rotation=np.zeros(3), local=np.ones(4))


def test_a_quaternion_with_negative_w_is_kept_as_the_same_rotation_with_w_positive() -> None:
    from scipy.spatial.transform import Rotation

    q = np.array([-0.5, 0.5, -0.5, 0.5])  # w < 0
    pose = BonePose(head=np.zeros(3), rotation=q, local=-q)
    assert pose.rotation[0] > 0.0 and pose.local[0] > 0.0
    # scipy's reading of both: the same rotation as q (independent of the sign rule)
    for kept in (pose.rotation, pose.local):
        turn = Rotation.from_quat(kept, scalar_first=True).inv() * Rotation.from_quat(
            q, scalar_first=True
        )
        assert turn.magnitude() < 1e-15


@pytest.mark.parametrize(
    ("mutate", "match"),
    [
        (lambda k: setattr(k.bones["hips"], "head", np.array([0.0, np.nan, 0.0])), "not finite"),
        (lambda k: setattr(k.bones["spine"], "local", np.array([2.0, 0, 0, 0])), "unit"),
        (lambda k: k.extra.update(bones=1), "reserved"),
        (lambda k: setattr(k, "time", float("inf")), "not finite"),
        # beyond what read_keyframes accepts (BAD_FILES: "magnitude at most 1e+09")
        (lambda k: setattr(k, "time", 1.5e9), "beyond"),
        (lambda k: setattr(k.bones["hips"], "head", np.array([0.0, -2e9, 0.0])), "beyond"),
    ],
)
def test_write_rejects_bad_values_and_writes_nothing(
    tmp_path: Path, mutate: Any, match: str
) -> None:
    key = make_key(np.random.default_rng(4), 1.0)
    mutate(key)
    with pytest.raises(ValueError, match=match):
        write_keyframes(tmp_path / "k.json", "doll", [key])
    assert list(tmp_path.iterdir()) == []


def test_write_rejects_unsorted_keys_and_bone_mismatch(tmp_path: Path) -> None:
    rng = np.random.default_rng(5)
    with pytest.raises(ValueError, match="not after"):
        write_keyframes(tmp_path / "k.json", "doll", [make_key(rng, 1.0), make_key(rng, 0.5)])
    other = make_key(rng, 2.0)
    del other.bones["spine"]
    with pytest.raises(ValueError, match="differ"):
        write_keyframes(tmp_path / "k.json", "doll", [make_key(rng, 1.0), other])
    assert list(tmp_path.iterdir()) == []


def valid_doc() -> dict:
    """A small valid document to break in one place."""

    def bones() -> dict:
        pose = {"head": [0.0, 1.0, 0.0], "rotation": [1.0, 0.0, 0.0, 0.0], "local": [0, 0, 1, 0]}
        return {"hips": pose, "l.arm": copy.deepcopy(pose)}

    keys = [{"time": t, "label": label, "bones": bones()} for t, label in ((0.0, "a"), (1.0, "b"))]
    return {"rig": "doll", "keys": keys}


def broken(edit: Any) -> str:
    doc = valid_doc()
    edit(doc)
    return json.dumps(doc)


def _pose(doc: dict, i: int = 0, bone: str = "hips") -> dict:
    return doc["keys"][i]["bones"][bone]


BAD_FILES = [
    ("not json {", ": expected JSON, got invalid text at line 1 column 1 (Expecting value)"),
    ("[1, 2]", ': expected a JSON object with "rig" and "keys", got an array of 2 items'),
    (broken(lambda d: d.pop("keys")), ":keys: expected an array of keys, got no such field"),
    (broken(lambda d: d.update(rig=3)), ":rig: expected the rig name (a string), got 3"),
    (
        broken(lambda d: d["keys"].append(7)),
        ':keys[2]: expected a key object with "time", "label" and "bones", got 7',
    ),
    (
        broken(lambda d: d["keys"][1].pop("label")),
        ":keys[1].label: expected a string, got no such field",
    ),
    (
        broken(lambda d: d["keys"][0].update(time="0")),
        ':keys[0].time: expected a finite number, got "0"',
    ),
    (
        broken(lambda d: _pose(d).update(head=[0.0, 1.0])),
        ":keys[0].bones.hips.head: expected an array of 3 numbers, got an array of 2 items",
    ),
    (
        broken(lambda d: _pose(d, 1, "l.arm").update(local=[1, 0, "x", 0])),
        ':keys[1].bones["l.arm"].local[2]: expected a finite number, got "x"',
    ),
    (
        broken(lambda d: _pose(d).update(head=[0, -2e9, 0])),
        ":keys[0].bones.hips.head[1]: expected a number of magnitude at most 1e+09, "
        "got -2000000000.0",
    ),
    (
        broken(lambda d: _pose(d).update(head=[0, True, 0])),
        ":keys[0].bones.hips.head[1]: expected a finite number, got true",
    ),
    (
        broken(lambda d: _pose(d).update(rotation=[2, 0, 0, 0])),
        ":keys[0].bones.hips.rotation: expected a unit quaternion [w, x, y, z], got norm 2",
    ),
    (
        broken(lambda d: d["keys"][1].update(time=0.0)),
        ":keys[1].time: expected a time after 0.0 s (keys sorted by time), got 0.0",
    ),
    (
        broken(lambda d: d["keys"][1].update(bones={"hips": d["keys"][0]["bones"]["hips"]})),
        ":keys[1].bones: expected the same bones as keys[0], got no bone 'l.arm'",
    ),
    (
        broken(lambda d: d["keys"][0]["bones"].update(hips=[])),
        ':keys[0].bones.hips: expected a bone pose with "head", "rotation" and "local", '
        "got an array of 0 items",
    ),
]


@pytest.mark.parametrize(("text", "message"), BAD_FILES)
def test_bad_files_give_one_clear_line(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "keyframes.json"
    path.write_text(text)
    with pytest.raises(KeyframesError) as info:
        read_keyframes(path)
    assert str(info.value) == f"{path}{message}"
    assert isinstance(info.value, PuppetError)


def test_nan_token_is_rejected(tmp_path: Path) -> None:
    """Python's json accepts NaN; the reader must not."""
    path = tmp_path / "keyframes.json"
    path.write_text(broken(lambda d: None).replace("[0.0, 1.0, 0.0]", "[0.0, NaN, 0.0]", 1))
    with pytest.raises(KeyframesError, match=r"head\[1\]: expected a finite number, got NaN$"):
        read_keyframes(path)


def test_unreadable_files(tmp_path: Path) -> None:
    with pytest.raises(KeyframesError, match=r"missing\.json: cannot read"):
        read_keyframes(tmp_path / "missing.json")
    path = tmp_path / "binary.json"
    path.write_bytes(b'{"rig": "\xff"}')
    with pytest.raises(KeyframesError, match="expected UTF-8 JSON"):
        read_keyframes(path)


def test_valid_doc_reads(tmp_path: Path) -> None:
    """The base of the broken documents is itself valid (so each case tests one fault)."""
    path = tmp_path / "keyframes.json"
    path.write_text(json.dumps(valid_doc()))
    rig, keys = read_keyframes(path)
    assert rig == "doll" and [k.label for k in keys] == ["a", "b"]
    assert np.array_equal(keys[1].bones["l.arm"].local, [0.0, 0.0, 1.0, 0.0])


def test_written_files_follow_the_shipped_schema(tmp_path: Path) -> None:
    """The writer's output validates against puppetcli/schemas/puppetcli.Keyframes.json (a
    third-party validator), and the schema is not vacuous: broken copies fail it."""
    jsonschema = pytest.importorskip("jsonschema")
    from puppetcli.mcap.trace import load_schema

    rng = np.random.default_rng(4)
    path = tmp_path / "keyframes.json"
    write_keyframes(path, "doll", [make_key(rng, 0.5, "a", line=3), make_key(rng, 1.0, "b")])
    validator = jsonschema.Draft202012Validator(load_schema("puppetcli.Keyframes"))
    doc = json.loads(path.read_text())
    assert list(validator.iter_errors(doc)) == []
    broken = []
    for change in (
        lambda d: d["keys"][0]["bones"]["hips"]["rotation"].pop(),  # 3 components
        lambda d: d["keys"][1]["bones"]["spine"].pop("local"),
        lambda d: d["keys"][0].pop("time"),
        lambda d: d["keys"][0]["bones"]["hips"]["head"].__setitem__(0, "0"),
        lambda d: d.__setitem__("rig", 7),
        lambda d: d["keys"][0]["bones"]["hips"]["local"].__setitem__(0, -0.5),  # w < 0
        lambda d: d["keys"][0]["bones"]["hips"]["local"].__setitem__(0, "1"),
    ):
        bad = copy.deepcopy(doc)
        change(bad)
        broken.append(bool(list(validator.iter_errors(bad))))
    assert broken == [True] * 7
    bones = doc["keys"][0]["bones"].values()
    assert all(b[f][0] >= 0.0 for b in bones for f in ("rotation", "local"))


def test_a_known_rotation_is_written_scalar_first(tmp_path: Path) -> None:
    """A bone turned by a non-symmetric rotation (ZXY Euler 30°, −20°, 45°) is written, as raw
    numbers in the file, as scipy's scalar-first quaternion of that rotation (w ≥ 0)."""
    from scipy.spatial.transform import Rotation

    from puppetcli.rig.load import load_rig
    from puppetcli.run.snapshot import capture
    from solver.model import build_model
    from solver.state import initial_state

    root = Path(__file__).resolve().parents[3]
    model = build_model(load_rig(root / "rigs/doll.yaml"))
    state = initial_state(model)
    b = model.bone_names.index("forearm_l")
    turn = Rotation.from_euler("ZXY", [30.0, -20.0, 45.0], degrees=True)
    expected = turn.as_quat(scalar_first=True)
    expected = expected if expected[0] >= 0 else -expected
    state.body_quat[b] = expected
    path = tmp_path / "keyframes.json"
    write_keyframes(path, "doll", [capture(model, state, "turned", {})])
    written = json.loads(path.read_text())["keys"][0]["bones"]["forearm_l"]["rotation"]
    np.testing.assert_allclose(written, expected, rtol=0, atol=1e-15)  # measured: equal
    assert abs(written[0] - np.cos(turn.magnitude() / 2)) < 1e-15  # w is the scalar part
