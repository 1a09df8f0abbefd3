"""Pins in a run of rigs/doll.yaml: they hold through grips, releases and touches until
unpinned, a slip is traced and holds where it slipped, and a whole-bone pin on a free root
gives the keys of a fixed root."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml
from click.testing import CliRunner
from mcap.reader import make_reader
from scipy.spatial.transform import Rotation

from puppetcli.cli import cli
from puppetcli.mcap.trace import read_trace
from puppetcli.run.pin_trace import CHANNELS as PIN_CHANNELS

ROOT = Path(__file__).resolve().parents[3]
DOLL = ROOT / "rigs" / "doll.yaml"

THROUGH = """\
pointer: {start: [0.70, 1.36, 0.0]}
actions:
  - key: rest
  - pin: {bone: head, orient: true}
  - grip: {bone: forearm_l, point: [0.24, 0, 0], position_only: true}
  - move: {by: [0.0, 0.2, 0.1], duration: 0.5}
  - release:
  - move: {to: [0.5, 1.6, 0.3], duration: 0.3}
  - touch: {to: [0.45, 1.5, 0.0], duration: 0.3}
  - key: held
  - unpin: head
  - wait: 0.2
"""

SLIP = """\
pointer: {start: [0.80, 1.36, 0.0]}
actions:
  - pin: {bone: hand_l, force_limit: 5}
  - grip: {bone: hand_l, point: [0.09, 0, 0], position_only: true}
  - move: {by: [0.0, 0.15, 0.0], duration: 0.5}
  - release:
  - move: {by: [0.0, 0.0, 0.3], duration: 0.2}
  - wait: 0.5
  - key: after
"""


def pose(tmp_path: Path, script: str, rig: Path = DOLL, name: str = "out") -> tuple[dict, dict]:
    """(keys by label, trace by topic) of ``puppetcli pose`` on ``script``."""
    path = tmp_path / f"{name}.yaml"
    path.write_text(script)
    out = tmp_path / name
    result = CliRunner().invoke(cli, ["pose", str(rig), str(path), "-o", str(out), "--no-render"])
    assert result.exit_code == 0, result.output
    keys = json.loads((out / "keyframes.json").read_text())["keys"]
    return {k["label"]: k for k in keys}, read_trace(out / "trace.mcap")


def test_a_pin_holds_through_grip_release_and_touch_until_unpinned(tmp_path):
    keys, trace = pose(tmp_path, THROUGH)
    rest, held = keys["rest"]["bones"]["head"], keys["held"]["bones"]["head"]
    assert np.linalg.norm(np.subtract(held["head"], rest["head"])) < 7.5e-9  # measured 1.5e-9 m
    assert np.max(np.abs(np.subtract(held["rotation"], rest["rotation"]))) < 3e-10  # 6.3e-11
    listed = [m["pins"] for _, m in trace["/puppet/pin_force"]]
    assert len(listed) == len(trace["/puppet/joints"])  # one message a step
    pinned = [[p["bone"] for p in pins] for pins in listed]
    assert pinned[0] == ["head"] and pinned[-1] == []  # pinned from the first step, then unpinned
    assert sum(p == ["head"] for p in pinned) == 220  # the moves, 0.5 + 0.3 + 0.3 s at 5 ms
    assert all(len(m["entities"][0]["spheres"]) == len(p) for (_, m), p in
               zip(trace["/puppet/pins"], pinned, strict=True))  # fmt: skip
    assert "/log" in trace and not trace["/log"]  # it never slipped


def test_a_pin_past_its_limit_slips_is_logged_and_holds_where_it_slipped(tmp_path):
    keys, trace = pose(tmp_path, SLIP)
    pins = [m["pins"][0] for _, m in trace["/puppet/pin_force"]]
    slipped = [p for p in pins if p["slipped"]]
    assert slipped
    # the box limit: a row of a slipping pin carries exactly 5 N, none more
    assert all(np.max(np.abs(p["force"])) == 5.0 for p in slipped)
    assert max(np.max(np.abs(p["force"])) for p in pins) <= 5.0
    (log,) = [m for _, m in trace["/log"]][:1]
    assert log["message"].startswith("pin on 'hand_l' slipped at t = ") and log["level"] == 3
    start, end = np.array(pins[0]["target"]), np.array(pins[-1]["target"])
    assert end[1] - start[1] > 0.03  # it slid up with the hand: measured 0.041 m
    # released, the hand stays where the pin now holds it: its centre (the capsule's middle,
    # 0.045 m along the bone from the head at rest) is at the pin's last target
    hand = keys["after"]["bones"]["hand_l"]
    centre = hand["head"] + Rotation.from_quat(hand["rotation"], scalar_first=True).apply(
        [0.045, 0.0, 0.0]
    )
    assert not pins[-1]["slipped"]
    assert np.linalg.norm(centre - end) < 7e-10  # measured 1.3e-10 m


WAVE = """\
pointer: {start: [0.70, 1.36, 0.0]}
actions:
  - grip: {bone: forearm_l, point: [0.24, 0.0, 0.0], position_only: true}
  - move: {by: [0.0, 0.25, 0.0], duration: 0.5}
  - release:
  - move: {by: [0.0, 0.0, 0.15], duration: 0.3}
  - key: raised
"""


def test_a_whole_bone_pin_on_a_free_root_gives_the_keys_of_a_fixed_root(tmp_path):
    free = tmp_path / "free.yaml"
    text = DOLL.read_text()
    assert "\nroot: fixed\n" in text
    free.write_text(text.replace("\nroot: fixed\n", "\nroot: free\n"))
    fixed, _ = pose(tmp_path, WAVE, name="fixed")
    pinned, _ = pose(tmp_path, "actions:\n  - pin: {bone: hips, orient: true}\n"
                     + WAVE.split("actions:\n")[1], free, "pinned")  # fmt: skip
    pinned_key = pinned["raised"]["bones"]
    worst = 0.0
    for bone, pose_fixed in fixed["raised"]["bones"].items():
        for field in ("head", "rotation"):
            worst = max(
                worst, np.max(np.abs(np.subtract(pose_fixed[field], pinned_key[bone][field])))
            )
    # measured 8.6e-9 (m and quaternion units): the pin rows' 1e-6 regularisation lets
    # the 10 kg hips give by micrometres under the arm's pull
    assert worst < 4.5e-8


def test_a_pinned_point_is_the_scripts_point_on_the_bone(tmp_path):
    # pinned at t = 0, the doll is in its rest pose: the target is the hand's head (the
    # rig's numbers) plus the script's point, world-aligned at rest
    script = "actions:\n  - pin: {bone: hand_l, point: [0.05, 0.01, -0.005]}\n  - wait: 0.01\n"
    _, trace = pose(tmp_path, script + "  - key: end\n")
    (pin,) = trace["/puppet/pin_force"][0][1]["pins"]
    hand = next(b for b in yaml.safe_load(DOLL.read_text())["bones"] if b["name"] == "hand_l")
    expected = np.add(hand["head"], [0.05, 0.01, -0.005])
    assert np.max(np.abs(np.array(pin["target"]) - expected)) < 1e-15  # measured 0


def test_the_pin_channels_follow_their_schemas(tmp_path):
    jsonschema = pytest.importorskip("jsonschema")
    pose(tmp_path, SLIP)
    checks: dict = {}  # topic → its schema's validator, made once
    with open(tmp_path / "out" / "trace.mcap", "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages(topics=list(PIN_CHANNELS)):
            if channel.topic not in checks:
                checks[channel.topic] = jsonschema.Draft202012Validator(json.loads(schema.data))
            checks[channel.topic].validate(json.loads(message.data))
    assert set(checks) == set(PIN_CHANNELS)
