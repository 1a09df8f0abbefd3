"""Page messages: every documented shape parses; malformed, hostile or absurd ones are
rejected with one line; the pointer is kept inside the device's workspace."""

from __future__ import annotations

import json

import numpy as np
import pytest

from puppetcli.live import protocol, recording
from puppetcli.spidar.strings import ANGLE_MAX
from solver import quat

BONES = ["hips", "forearm_l"]


def parse(obj):
    return protocol.parse(obj if isinstance(obj, str) else json.dumps(obj), BONES)


def test_the_documented_messages_parse():
    seq, c = parse({"type": "pointer", "seq": 4, "pos": [0, 1, 2], "quat": [2, 0, 0, 0]})
    assert seq == 4 and c == protocol.PointerTarget((0.0, 1.0, 2.0), (1.0, 0.0, 0.0, 0.0))
    _, c = parse({"type": "grip", "bone": "forearm_l", "point": [0.1, 1.4, 0]})
    assert c.bone == "forearm_l" and np.array_equal(c.point, [0.1, 1.4, 0])
    assert parse({"type": "grip"})[1] == recording.Grip()
    _, c = parse({"type": "grip", "bone": "hips", "point": [0, 1, 0], "position_only": False})
    assert c.position_only is False
    assert parse({"type": "grip", "position_only": True})[1] == recording.Grip(position_only=True)
    assert parse({"type": "release"})[1] == recording.Release()
    assert parse({"type": "touch", "on": True})[1] == recording.Touch(True)
    assert parse({"type": "position_only", "on": False})[1] == protocol.PositionOnly(False)
    assert parse({"type": "key", "label": "arm up"})[1] == recording.Key("arm up")
    assert parse({"type": "key"})[1] == recording.Key(None)
    assert parse({"type": "undo"})[1] == recording.Undo()
    assert parse({"type": "pause", "on": True})[1] == protocol.Pause(True)
    assert parse({"type": "stop"})[1] == protocol.Stop()
    assert parse({"type": "ping", "t": 12.5})[1] == protocol.Ping(12.5)
    _, c = parse({"type": "pin", "bone": "hips", "point": [0, 1, 0], "orient": True})
    assert (c.bone, c.orient) == ("hips", True) and np.array_equal(c.point, [0, 1, 0])
    assert parse({"type": "pin", "bone": "hips", "point": [0, 1, 0]})[1].orient is False
    assert parse({"type": "unpin", "bone": "forearm_l"})[1] == recording.Unpin("forearm_l")
    assert parse({"type": "unpin"})[1] == recording.Unpin(None)


BAD = [
    ("not json", "expected a JSON object"),
    ("[1, 2]", "type: expected one of"),
    ('{"type": "pointer", "pos": [NaN, 0, 0], "quat": [1, 0, 0, 0]}', "expected finite numbers"),
    ('{"type": "pointer", "pos": [1e400, 0, 0], "quat": [1, 0, 0, 0]}', "pos: expected a number"),
    ({"type": "pointer", "pos": [1e9, 0, 0], "quat": [1, 0, 0, 0]}, "pos: expected a number"),
    ({"type": "pointer", "pos": [0, 0], "quat": [1, 0, 0, 0]}, "pos: expected 3 numbers"),
    ({"type": "pointer", "pos": [0, 0, "1"], "quat": [1, 0, 0, 0]}, "pos: expected a number"),
    ({"type": "pointer", "pos": [0, 0, True], "quat": [1, 0, 0, 0]}, "pos: expected a number"),
    ({"type": "pointer", "pos": [0, 0, 0], "quat": [0, 0, 0, 0]}, "expected a unit quaternion"),
    ({"type": "grip", "bone": "tail", "point": [0, 0, 0]}, "bone: expected a bone of the rig"),
    ({"type": "grip", "bone": "hips"}, "point: expected 3 numbers"),
    ({"type": "touch", "on": 1}, "on: expected true or false"),
    ({"type": "grip", "position_only": "no"}, "position_only: expected true or false"),
    ({"type": "key", "label": "x" * 65}, "label: expected printable text of at most 64"),
    ({"type": "key", "label": "a\nb"}, "label: expected printable text"),
    ({"type": "pin", "bone": "tail", "point": [0, 0, 0]}, "bone: expected a bone of the rig"),
    ({"type": "pin", "bone": "hips"}, "point: expected 3 numbers"),
    ({"type": "pin", "bone": "hips", "point": [0, 0, 0], "orient": 1}, "orient: expected true"),
    ({"type": "unpin", "bone": 3}, "bone: expected a bone of the rig"),
    ({"type": "launch"}, "type: expected one of"),
    ({"type": "stop", "seq": -1}, "seq: expected a non-negative integer"),
    ({"type": "stop", "seq": 1.5}, "seq: expected a non-negative integer"),
    ("[" * 100_000, "expected a message of at most 4096 bytes"),
    ("[" * 3000 + "]" * 3000, "expected a message of at most"),
    ("[" * 2000 + "]" * 2000, "expected a JSON object"),  # too deep for the parser
]


@pytest.mark.parametrize(("message", "why"), BAD)
def test_bad_messages_are_rejected_with_one_line(message, why):
    with pytest.raises(protocol.Rejected) as info:
        parse(message)
    text = str(info.value)
    assert why in text and "\n" not in text


def test_the_target_is_kept_in_the_workspace_and_the_rotation_limit():
    rng = np.random.default_rng(5)
    centre, radius = np.array([0.0, 0.9, 0.0]), 1.4
    for _ in range(200):
        orientation = quat.normalize(rng.normal(size=4))
        pos, q = rng.normal(size=3) * 2.0, quat.normalize(rng.normal(size=4))
        got = protocol.clamp_target(protocol.PointerTarget(tuple(pos), tuple(q)), centre,
                                    radius, orientation)  # fmt: skip
        dist = np.linalg.norm(pos - centre)
        expect_pos = pos if dist <= radius else centre + (pos - centre) * radius / dist
        np.testing.assert_allclose(got.pos, expect_pos, atol=1e-12)
        home = quat.mul(quat.mul(quat.conj(orientation), np.array(got.quat)), orientation)
        angle = np.linalg.norm(quat.log(home))
        assert angle <= ANGLE_MAX + 1e-9
        original = np.linalg.norm(quat.log(quat.mul(quat.mul(quat.conj(orientation), q),
                                                     orientation)))  # fmt: skip
        if original <= ANGLE_MAX:  # within the limit: untouched (up to a sign)
            assert (
                min(np.abs(np.array(got.quat) - q).max(), np.abs(np.array(got.quat) + q).max())
                < 1e-12
            )
        else:  # beyond: the same axis, the angle at the limit
            assert angle == pytest.approx(ANGLE_MAX, abs=1e-9)
