"""Property-based round trips (Hypothesis) of keyframes.json.

Random keys (any bone and rig names, labels, extra fields, strictly increasing times, heads,
rotations drawn as scipy rotation vectors) written by ``write_keyframes``.  Oracles that
share no code with the writer or reader: the shipped JSON Schema
(puppetcli/schemas/puppetcli.Keyframes.json, loaded here as plain JSON) checked by
``jsonschema``; the raw numbers read with the standard ``json`` module and turned into
rotations by scipy's scalar-first ``Rotation.from_quat`` (w, x, y, z), the scalar part also
checked as cos(angle / 2); and ``read_keyframes`` giving back exactly the keys written.

Derandomized: the same examples on every run.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import jsonschema
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from puppetcli.run.keyframes import BonePose, Keyframe, read_keyframes, write_keyframes

ROOT = Path(__file__).resolve().parents[3]
SCHEMA = json.loads((ROOT / "puppetcli" / "schemas" / "puppetcli.Keyframes.json").read_text())
VALIDATOR = jsonschema.Draft202012Validator(SCHEMA)
SETTINGS = settings(max_examples=60, derandomize=True, deadline=None)
# The raw quaternion's rotation vs the one drawn: only scipy's as_quat/from_quat round trip
# separates them (the file holds the very numbers written).  Measured over 20,000 rotations:
ROTATION_TOL = 1e-15  # rad: 2.1e-16
SCALAR_TOL = 1e-15  # |w| vs cos(angle / 2): 2.2e-16
LARGEST = 1e9  # docs: numbers beyond 1e9 in magnitude are refused by the reader

names = st.text(min_size=1, max_size=12)
numbers = st.floats(-LARGEST, LARGEST, allow_nan=False)
positions = st.tuples(numbers, numbers, numbers).map(list)
# Rotation vectors of length at most π (every rotation), components drawn independently.
rotvecs = st.tuples(*[st.floats(-math.pi, math.pi)] * 3).filter(
    lambda v: np.linalg.norm(v) <= math.pi
)
json_scalars = st.one_of(
    st.none(), st.booleans(), st.integers(-(2**53), 2**53), numbers, st.text(max_size=8)
)
json_values = st.recursive(
    json_scalars,
    lambda inner: st.one_of(
        st.lists(inner, max_size=3), st.dictionaries(st.text(max_size=6), inner, max_size=3)
    ),
    max_leaves=6,
)
extras = st.dictionaries(
    st.text(max_size=10).filter(lambda k: k not in ("time", "label", "bones")),
    json_values,
    max_size=3,
)


@st.composite
def keysets(draw) -> tuple[str, list[Keyframe], list[dict[str, tuple[list, Rotation, Rotation]]]]:
    """(rig name, keys, the drawn (head, world Rotation, local Rotation) per key and bone)."""
    bones = draw(st.lists(names, min_size=1, max_size=5, unique=True))
    times = sorted(draw(st.lists(numbers, min_size=1, max_size=4, unique=True)))
    keys, drawn = [], []
    for t in times:
        poses, chosen = {}, {}
        for name in bones:
            head = draw(positions)
            world = Rotation.from_rotvec(draw(rotvecs))
            local = Rotation.from_rotvec(draw(rotvecs))
            chosen[name] = (head, world, local)
            poses[name] = BonePose(
                head=head,
                rotation=world.as_quat(scalar_first=True),
                local=local.as_quat(scalar_first=True),
            )
        keys.append(Keyframe(time=t, label=draw(st.text(max_size=12)), bones=poses,
                             extra=draw(extras)))  # fmt: skip
        drawn.append(chosen)
    return draw(names), keys, drawn


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("keyframes_properties")


@SETTINGS
@given(case=keysets())
def test_written_keys_follow_the_schema_hold_scalar_first_quaternions_and_read_back(
    folder, case
) -> None:
    rig, keys, drawn = case
    path = folder / "keyframes.json"
    write_keyframes(path, rig, keys)
    doc = json.loads(path.read_text(encoding="utf-8"))
    errors = [e.message for e in VALIDATOR.iter_errors(doc)]
    assert errors == []
    assert doc["rig"] == rig
    assert len(doc["keys"]) == len(keys)
    for written, key, chosen in zip(doc["keys"], keys, drawn, strict=True):
        assert written["time"] == key.time and written["label"] == key.label
        assert {k: v for k, v in written.items() if k not in ("time", "label", "bones")} == (
            key.extra
        )
        assert list(written["bones"]) == list(chosen)
        for name, (head, world, local) in chosen.items():
            bone = written["bones"][name]
            assert bone["head"] == head
            for field, rotation in (("rotation", world), ("local", local)):
                raw = bone[field]  # [w, x, y, z] as written
                back = Rotation.from_quat(raw, scalar_first=True)
                assert (back.inv() * rotation).magnitude() <= ROTATION_TOL, (name, field, raw)
                assert abs(abs(raw[0]) - math.cos(rotation.magnitude() / 2.0)) <= SCALAR_TOL
    rig_back, keys_back = read_keyframes(path)
    assert rig_back == rig
    assert keys_back == keys  # times, labels, extras, and every number bit for bit
