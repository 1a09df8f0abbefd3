"""Poses read back from a trace (written here with TraceWriter), trace sheets and videos."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from test_render_fixtures import DOLL, doll, keys

from puppetcli.mcap.trace import TraceWriter, foxglove_time, load_schema, scene_update
from puppetcli.render.inputs import trace_poses
from puppetcli.render.video import frame_indices
from puppetcli.rig.skeleton import key_pose
from solver import quat


def write_trace(path: Path, skel, ks, events: bool = True, pointer: bool = True) -> None:
    """A trace of the keys ``ks`` (one step per key), with key events and a gripping pointer."""
    joints = [n for n, p in zip(skel.names, skel.parents, strict=True) if p >= 0]
    zeros = np.zeros((len(joints), 3))
    with TraceWriter(path, skel.names, skel.parents, joints) as w:
        w.add_channel("/puppet/keyframe", "puppetcli.KeyframeEvent",
                      load_schema("puppetcli.KeyframeEvent"))  # fmt: skip
        if pointer:
            w.add_channel("/puppet/pointer", "foxglove.SceneUpdate",
                          load_schema("foxglove.SceneUpdate"))  # fmt: skip
        for i, k in enumerate(ks):
            head, tail, rot = key_pose(skel, k)
            stats = dict(rows=0, contacts=0, iterations=0, residual=0.0, solver="direct")
            w.write_step(k.time, joint_rotation=zeros, joint_elastic=zeros, joint_torque=zeros,
                         bone_head=head, bone_tail=tail, bone_quat=rot, stats=stats)  # fmt: skip
            if events and i % 2 == 0:
                event = {"t": k.time, "label": k.label, "line": 1, "index": i + 1}
                w.write("/puppet/keyframe", k.time, event)
            if pointer:
                grip = tail[skel.names.index("hand_l")]
                seg = np.array([[grip + [0.0, 0.1, 0.0], grip]])
                scene = scene_update(
                    foxglove_time(round(k.time * 1e9)), "pointer", seg, seg[:, 0], {}, {}, 0.04
                )
                w.write("/puppet/pointer", k.time, scene)


def test_trace_poses_round_trip(tmp_path: Path) -> None:
    """Heads, tails and world rotations (composed from /tf) come back as written."""
    _, skel = doll()
    ks = keys(skel, 5)
    write_trace(tmp_path / "t.mcap", skel, ks)
    steps, moments = trace_poses(tmp_path / "t.mcap", skel)
    assert [p.time for p in steps] == pytest.approx([k.time for k in ks], abs=1e-9)
    for pose, k in zip(steps, ks, strict=True):
        head, tail, rot = key_pose(skel, k)
        assert np.allclose(pose.head, head, atol=1e-12)
        assert np.allclose(pose.tail, tail, atol=1e-12)
        assert np.allclose(np.abs(np.sum(pose.rot * rot, axis=1)), 1.0, atol=1e-12)
        hand = tail[skel.names.index("hand_l")]
        assert np.allclose(pose.grip, hand) and np.allclose(pose.pointer, hand + [0, 0.1, 0])
        assert pose.pointer_radius == pytest.approx(0.02)
    assert [(m.label, m.time) for m in moments] == [(ks[i].label, ks[i].time) for i in (0, 2, 4)]


def test_trace_without_events_or_tf_rotations(tmp_path: Path) -> None:
    """No key events: evenly spaced steps.  Rotations then still map rest axes onto bones."""
    _, skel = doll()
    ks = keys(skel, 20)
    write_trace(tmp_path / "t.mcap", skel, ks, events=False, pointer=False)
    steps, moments = trace_poses(tmp_path / "t.mcap", skel)
    assert len(moments) == 9 and moments[0] is steps[0] and moments[-1] is steps[-1]
    assert all(p.pointer is None for p in steps)
    rest_axis = skel.tail0 - skel.head0
    axis = quat.rotate(steps[-1].rot, rest_axis)
    assert np.allclose(axis, steps[-1].tail - steps[-1].head, atol=1e-12)


def test_frame_indices() -> None:
    times = [0.005 * i for i in range(1, 301)]  # 5 ms steps from 5 ms to 1.5 s
    idx = frame_indices(times, 30.0)
    assert len(idx) == int((1.5 - 0.005) * 30) + 1
    for k, i in enumerate(idx):
        t = times[0] + k / 30.0
        assert times[i] <= t + 1e-9 and (i + 1 == len(times) or times[i + 1] > t + 1e-9)
    assert frame_indices([], 30.0) == []


@pytest.mark.parametrize("suffix", [".avi", ".mp4"])
def test_video_of_a_trace(tmp_path: Path, suffix: str) -> None:
    from click.testing import CliRunner

    from puppetcli.cli import cli

    _, skel = doll()
    write_trace(tmp_path / "t.mcap", skel, keys(skel, 11))  # 0 … 1.0 s
    out = tmp_path / f"v{suffix}"
    args = ["render", str(tmp_path / "t.mcap"), "--rig", str(DOLL), "--video", str(out),
            "--size", "64x48", "--fps", "10", "-o", str(tmp_path / "s.png")]  # fmt: skip
    result = CliRunner().invoke(cli, args)
    if "cannot encode video" in result.output:
        pytest.skip(f"no {suffix} encoder in this OpenCV build")
    assert result.exit_code == 0, result.output
    assert "11 frames at 10 fps" in result.output
    capture = cv2.VideoCapture(str(out))
    frames = []
    while True:
        ok, frame = capture.read()
        if not ok:
            break
        frames.append(frame)
    assert len(frames) == 11 and frames[0].shape == (48, 64, 3)
    sheet = cv2.imread(str(tmp_path / "s.png"))
    assert sheet.shape == (2 * 48, 4 * 64, 3)  # 6 key events (keys 1, 3 … 11): 4 + 2 panels
