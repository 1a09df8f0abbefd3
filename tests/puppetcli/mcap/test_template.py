"""Message templates: a filled template is the message json.dumps writes, byte for byte."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from puppetcli.jsontext import json_bytes
from puppetcli.mcap.template import MessageTemplate, Slot, slots
from puppetcli.mcap.trace import TraceWriter, bones_scene, frame_transforms

NAMES = ["hips", "spine", "head", "arm_l", "hand_l"]
PARENTS = [-1, 0, 1, 1, 3]
JOINTS = ["spine", "neck", "shoulder_l", "wrist_l"]


def _numbers(rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
    """Floats of every magnitude and sign, with exact zeros and integers among them."""
    a = rng.normal(size=shape) * 10.0 ** rng.integers(-12, 12, size=shape)
    a.flat[::7] = 0.0
    a.flat[3::11] = np.round(a.flat[3::11])
    return a


def test_groups_go_where_their_slots_are_in_any_order():
    # The groups are filled in another order than the message lists them.
    shape = {"a": [Slot("y", 1), {"b": Slot("x")}], "c": Slot("y", 0), "d": "{not a slot}"}
    template = MessageTemplate(shape, [("x", 1), ("y", 2)])
    message = json.loads(template.fill([0.5, -2, 1e300]))
    assert message == {"a": [1e300, {"b": 0.5}], "c": -2, "d": "{not a slot}"}


@pytest.mark.parametrize("seed", range(5))
def test_filled_step_messages_are_the_bytes_json_writes(tmp_path, seed):
    rng = np.random.default_rng(seed)
    writer = TraceWriter(tmp_path / "t.mcap", NAMES, PARENTS, JOINTS)
    tf, bones, joints = writer._step_templates()
    writer.close()
    nb, nj = len(NAMES), len(JOINTS)
    head, tail = _numbers(rng, (nb, 3)), _numbers(rng, (nb, 3))
    rot = rng.normal(size=(nb, 4))
    joint = _numbers(rng, (nj, 3, 3))
    ns = int(rng.integers(0, 10**12))
    sec, nsec = divmod(ns, 10**9)
    t = ns / 1e9
    want_tf = frame_transforms(ns, NAMES, np.array(PARENTS), head, rot)
    moves = [[v["x"], v["y"], v["z"]] for v in (f["translation"] for f in want_tf["transforms"])]
    turns = [
        [q["w"], q["x"], q["y"], q["z"]] for q in (f["rotation"] for f in want_tf["transforms"])
    ]
    filled = tf.fill([sec, nsec, *np.ravel(moves).tolist(), *np.ravel(turns).tolist()])
    assert filled == json_bytes(want_tf)
    filled = bones.fill([sec, nsec, *head.ravel().tolist(), *tail.ravel().tolist()])
    assert filled == json_bytes(bones_scene(ns, head, tail))
    want_joints = {
        "t": t,
        "joints": {
            name: {"rotation": r.tolist(), "elastic": e.tolist(), "torque": f.tolist()}
            for name, (r, e, f) in zip(JOINTS, joint, strict=True)
        },
    }
    assert joints.fill([t, *joint.ravel().tolist()]) == json_bytes(want_joints)


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_a_number_json_refuses_is_refused(bad):
    template = MessageTemplate({"v": slots("v", (3,)).tolist()}, [("v", 3)])
    with pytest.raises(ValueError, match="Out of range float"):
        template.fill([1.0, bad, 2.0])
    with pytest.raises(ValueError, match="Out of range float"):
        json_bytes({"v": [1.0, bad, 2.0]})  # the same as json's


def test_a_template_must_use_each_number_and_get_each():
    with pytest.raises(ValueError, match="uses 2 of its 3 numbers"):
        MessageTemplate({"v": [Slot("v", 0), Slot("v", 2)]}, [("v", 3)])
    template = MessageTemplate({"v": [Slot("v", 0), Slot("v", 1)]}, [("v", 2)])
    with pytest.raises(ValueError, match="expected 2 numbers, got 3"):
        template.fill([1.0, 2.0, 3.0])
