"""A live session (driven here in-process, as the server drives it) is a device session:
`pose` replays it to the same keys, its haptic channels equal the replay trace's, and a
recording killed after a flush still replays up to it."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from mcap.reader import make_reader

from puppetcli.cli import cli
from puppetcli.live.recording import Grip, Key, LiveRecording, Release, Touch, Undo
from puppetcli.mcap.record import fit_workspace
from puppetcli.mcap.session import is_session, read_session
from puppetcli.rig.load import load_rig
from puppetcli.run.keyframes import read_keyframes
from puppetcli.spidar import preset
from solver.observe import bone_heads, bone_tails

ROOT = Path(__file__).resolve().parents[3]
DOLL = ROOT / "rigs/doll.yaml"


def steps(live: LiveRecording, seconds: float) -> None:
    for _ in range(round(seconds / live.model.options.h)):
        live.step()


def forearm_middle(live: LiveRecording) -> np.ndarray:
    m, s = live.model, live.runner.state
    b = m.bone_names.index("forearm_l")
    return 0.5 * (bone_heads(m, s)[b] + bone_tails(m, s)[b])


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """A session: click the left forearm, pull it up 0.25 m in 1 s, key, release, wait 1 s,
    key; touching switched on and off; a key taken and undone; the file copied after a
    flush half-way (as a kill would leave it)."""
    tmp = tmp_path_factory.mktemp("live")
    spec = load_rig(DOLL)
    dev = preset("SpidarG6X3R")
    ws = fit_workspace(np.array([[-1.3, -0.3, -1.0], [1.3, 2.0, 1.0]]), dev)
    path = tmp / "s.mcap"
    with open(path, "wb") as f:
        live = LiveRecording(spec, f, dev, ws, None, np.array([0.7, 1.4, 0.4]),
                             np.array([1.0, 0, 0, 0]), {"test": True})  # fmt: skip
        steps(live, 0.2)
        start = forearm_middle(live)
        live.submit(Grip("forearm_l", start))
        steps(live, 0.01)
        n = round(1.0 / live.model.options.h)
        for i in range(1, n + 1):
            live.set_target(start + [0.0, 0.25 * i / n, 0.0], (1.0, 0.0, 0.0, 0.0))
            live.step()
        live.submit(Key("raised"))
        live.submit(Release())
        steps(live, 0.01)
        live.flush()
        shutil.copyfile(path, tmp / "killed.mcap")
        live.set_target(start + [0.0, 0.25, 0.4], (1.0, 0.0, 0.0, 0.0))
        steps(live, 1.0)
        live.submit(Touch(True))
        live.submit(Key(None))
        steps(live, 0.05)
        live.submit(Touch(False))
        live.submit(Key("undone"))
        steps(live, 0.05)
        live.submit(Undo())
        steps(live, 0.05)
        keys = list(live.runner.keys)
        live.close()
    return tmp, path, keys


def replay(path: Path, out: Path) -> list:
    result = CliRunner().invoke(cli, ["pose", str(DOLL), str(path), "-o", str(out), "--no-render"])
    assert result.exit_code == 0, result.output
    return read_keyframes(out / "keyframes.json")[1]


def worst_difference(a: list, b: list) -> float:
    assert [k.label for k in a] == [k.label for k in b]
    assert [k.time for k in a] == [k.time for k in b]
    return max(
        float(np.max(np.abs(np.concatenate((x.bones[n].local - y.bones[n].local,
                                            x.bones[n].head - y.bones[n].head)))))
        for x, y in zip(a, b, strict=True) for n in x.bones
    )  # fmt: skip


def test_the_replay_gives_the_live_keys(recorded):
    tmp, path, live_keys = recorded
    assert [k.label for k in live_keys] == ["raised", "key 2"]  # "undone" was undone
    keys = replay(path, tmp / "out")
    assert worst_difference(live_keys, keys) == 0.0  # the same floats


def test_the_elbow_kept_most_of_its_bend(recorded):
    _, _, keys = recorded
    angle = [
        2 * math.degrees(math.acos(min(1.0, abs(k.bones["forearm_l"].local[0])))) for k in keys
    ]
    assert angle[0] > 18.0  # measured 21.6°: the pull bent the elbow
    assert angle[1] > 0.85 * angle[0]  # measured 19.9° (92 %): plastic, kept after release


def test_the_session_holds_a_devices_record(recorded):
    _, path, _ = recorded
    session = read_session(path)
    assert session.complete and session.counts is None
    ticks = session.pose_time
    np.testing.assert_allclose(np.diff(ticks), 0.001, rtol=0, atol=2e-15)  # 1 ms ticks: 3.3e-16
    buttons = [(e.message["button"], e.message["state"]) for e in session.events]
    assert buttons[0] == ("touch", "up")  # live touching starts off
    for event in [("grip", "down"), ("grip", "up"), ("key", "down"), ("undo", "down"),
                  ("touch", "down")]:  # fmt: skip
        assert event in buttons
    grip = next(e.message for e in session.events if e.message["button"] == "grip")
    assert grip["bone"] == "forearm_l" and grip["gains"]["position_only"] is True


def channel(path: Path, topic: str) -> list[dict]:
    with open(path, "rb") as f:
        return [json.loads(m.data) for _, _, m in make_reader(f).iter_messages(topics=[topic])]


def test_the_haptic_channels_equal_the_replay_traces(recorded):
    tmp, path, _ = recorded
    out = tmp / "traced"
    result = CliRunner().invoke(cli, ["pose", str(DOLL), str(path), "-o", str(out), "--no-render"])
    assert result.exit_code == 0
    for topic in ("/haptic/wrench", "/spidar/tensions"):
        live, traced = channel(path, topic), channel(out / "trace.mcap", topic)
        assert len(live) == len(traced) > 400 and live == traced  # the same numbers


def test_a_killed_recording_replays_up_to_its_last_flush(recorded):
    tmp, _, live_keys = recorded
    killed = tmp / "killed.mcap"
    assert not read_session(killed).complete
    keys = replay(killed, tmp / "killed-out")
    assert worst_difference(live_keys[:1], keys) == 0.0  # the same floats


def test_touching_follows_the_touch_switch(tmp_path):
    """The free pointer swept through the left forearm: with touching off it passes through
    (no force on the hand); switched on outside the doll it strikes the forearm; switched on
    inside, it touches nothing until it is clear (as after a release)."""
    spec = load_rig(DOLL)
    dev = preset("SpidarG6X3R")
    ws = fit_workspace(np.array([[-1.3, -0.3, -1.0], [1.3, 2.0, 1.0]]), dev)

    def sweep(switch_at: float | None) -> list[float]:
        """Peak force on the hand over a 0.6 s sweep from 0.3 m in front of the forearm to
        0.3 m behind it; touching switched on at that distance in front (None: never)."""
        with open(tmp_path / "t.mcap", "wb") as f:
            live = LiveRecording(spec, f, dev, ws, None, np.array([0.45, 1.36, 0.3]),
                                 np.array([1.0, 0, 0, 0]), {})  # fmt: skip
            mid, h = forearm_middle(live), live.model.options.h
            live.filter.jump(mid + [0, 0, 0.3], (1.0, 0.0, 0.0, 0.0))
            live.set_target(mid + [0, 0, 0.3], (1.0, 0.0, 0.0, 0.0))
            peak, n = 0.0, round(0.6 / h)
            for i in range(n + 1):
                z = 0.3 - 0.6 * i / n
                if switch_at is not None and abs(z - switch_at) < 0.5 * 0.6 / n:
                    live.submit(Touch(True))
                live.set_target(mid + [0, 0, z], (1.0, 0.0, 0.0, 0.0))
                live.step()
                peak = max(peak, float(np.linalg.norm(live.tap.requested[0])))
            live.close()
        return peak

    assert sweep(None) == 0.0
    assert sweep(0.25) > 120.0  # measured 594 N at 1 m/s: the ball strikes the forearm
    assert sweep(0.0) == 0.0  # switched on inside the forearm: suspended until clear


def test_render_draws_a_session_as_its_replay(recorded):
    """`render SESSION.mcap` replays the session and draws its keys (a sheet) and every step
    (a video); a killed one too, with the warning; a trace is not taken for a session."""
    tmp, path, live_keys = recorded
    args = ["render", str(path), "--rig", str(DOLL), "-o", str(tmp / "sheet.png")]
    result = CliRunner().invoke(cli, [*args, "--video", str(tmp / "s.avi")])
    assert result.exit_code == 0, result.output
    assert f"{tmp / 'sheet.png'}: {len(live_keys)} panels" in result.output
    assert "frames at 30 fps" in result.output and (tmp / "s.avi").stat().st_size > 0
    killed = CliRunner().invoke(cli, ["render", str(tmp / "killed.mcap"), "--rig", str(DOLL),
                                      "-o", str(tmp / "killed.png")])  # fmt: skip
    assert killed.exit_code == 0 and "the recording ended abruptly" in killed.stderr
    assert is_session(path) and is_session(tmp / "killed.mcap")
    assert not is_session(tmp / "traced" / "trace.mcap") and not is_session(DOLL)
