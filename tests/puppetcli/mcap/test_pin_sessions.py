"""Pins in sessions (format 3): recorded from a script, replayed as its pins; sessions of
formats 1 and 2 (written here as the code before pins wrote them) still replay; every bad
pin event is one error line."""

from __future__ import annotations

from pathlib import Path

import pytest
from test_session_files import GOOD_META, KEY, bad, read_all, run, ticks, write_raw

from puppetcli.mcap.trace import read_trace
from puppetcli.run.keyframes import read_keyframes

ROOT = Path(__file__).resolve().parents[3]
DOLL = ROOT / "rigs/doll.yaml"
PIN = ROOT / "scripts/pin_pose.yaml"


def button(t: float, **fields) -> tuple:
    return ("/spidar/buttons", t, fields)


PINNED = [
    button(0.01, button="pin", state="down", bone="head", orient=True, force_limit=500.0),
    button(0.015, button="pin", state="down", bone="hand_l", point=[0.05, 0.0, 0.0]),
    button(0.03, button="key", state="down", label="pinned"),
    button(0.04, button="pin", state="up", bone="head"),
    button(0.05, button="pin", state="up"),
]


def test_recorded_pins_are_buttons_and_replay_as_the_scripts_pins(tmp_path):
    session = tmp_path / "pins.mcap"
    assert run("record", DOLL, PIN, "-o", session).exit_code == 0
    pins = [m for m in read_all(session)["/spidar/buttons"] if m["button"] == "pin"]
    assert [(m["state"], m.get("bone"), m.get("orient")) for m in pins] == [
        ("down", "foot_l", True), ("down", "foot_r", True), ("down", "head", True),
        ("up", None, None),
    ]  # fmt: skip
    assert "force_limit" not in pins[0]  # no limit: none written


def test_a_hand_written_pin_session_replays_its_pins(tmp_path):
    path = write_raw(tmp_path / "p.mcap", ticks() + PINNED, meta={**GOOD_META, "format": "3"})
    result = run("pose", DOLL, path, "-o", tmp_path / "out", "--no-render")
    assert result.exit_code == 0, result.output
    steps = read_trace(tmp_path / "out" / "trace.mcap")["/puppet/pin_force"]
    held = {round(m["t"], 3): sorted(p["bone"] for p in m["pins"]) for _, m in steps}
    # an event acts at the first step boundary at or after it (h = 5 ms): the step ending at
    # 0.015 is the first with the head's pin, the one ending at 0.02 the first with both
    assert held[0.015] == ["head"] and held[0.02] == held[0.04] == ["hand_l", "head"]
    assert held[0.045] == ["hand_l"] and held[0.055] == []
    _, keys = read_keyframes(tmp_path / "out" / "keyframes.json")
    assert [k.label for k in keys] == ["pinned"]


@pytest.mark.parametrize("version", ["1", "2"])
def test_sessions_written_before_pins_still_replay(tmp_path, version):
    events = KEY
    if version == "2":  # format 2 added the touch and undo buttons
        events = KEY + [button(0.03, button="touch", state="down"),
                        button(0.04, button="undo", state="down")]  # fmt: skip
    path = write_raw(tmp_path / "old.mcap", ticks() + events, meta={**GOOD_META, "format": version})
    result = run("pose", DOLL, path, "-o", tmp_path / "out", "--no-render")
    assert result.exit_code == 0, result.output
    _, keys = read_keyframes(tmp_path / "out" / "keyframes.json")
    assert [k.label for k in keys] == (["a"] if version == "1" else [])
    assert "/puppet/pin_force" not in read_trace(tmp_path / "out" / "trace.mcap")


BAD = [
    ([button(0.01, button="pin", state="up", bone="head")],
     "bone: expected a pinned bone, got 'head'"),
    ([button(0.01, button="pin", state="down", bone="nose")],
     "bone: expected a bone of the rig, got 'nose'"),
    (PINNED[:1] * 2, "bone: expected a bone that is not pinned yet, got 'head'"),
    ([button(0.01, button="pin", state="down")], "bone: expected a bone to pin, got None"),
    ([button(0.01, button="pin", state="down", bone="head", force_limit=-1.0)],
     "force_limit: expected a finite number > 0, got -1.0"),
    ([button(0.01, button="pin", state="down", bone="head", orient="yes")],
     "orient: expected a bool, got 'yes'"),
]  # fmt: skip


@pytest.mark.parametrize(("events", "message"), BAD, ids=[m.split(":")[0] + str(i) for i, (_, m)
                                                          in enumerate(BAD)])  # fmt: skip
def test_a_bad_pin_event_is_one_line(tmp_path, events, message):
    path = write_raw(tmp_path / "bad.mcap", ticks() + events, meta={**GOOD_META, "format": "3"})
    got = bad(tmp_path, path)
    assert got.startswith("/spidar/buttons[") and got.endswith(message), got
