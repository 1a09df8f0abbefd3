"""CLI tests for ``rig from-bvh`` and ``convert``: outputs, exit codes, one-line errors.

Independent values: the written BVH is read by the third-party ``bvh`` package
(test_bvh_fixtures.independent_fk) and compared with the keys of ``pose``'s
keyframes.json, and with the script's timeline.
"""

from __future__ import annotations

import math
from pathlib import Path

import bvh as bvh_package
import numpy as np
import pytest
from click.testing import CliRunner, Result
from test_bvh_fixtures import independent_fk, make_bvh
from test_bvh_read import BAD, SMALL

from puppetcli.cli import cli
from puppetcli.rig.load import load_rig
from puppetcli.rig.skeleton import Skeleton
from puppetcli.run.keyframes import read_keyframes

ROOT = Path(__file__).resolve().parents[3]
DOLL = ROOT / "rigs" / "doll.yaml"
ARM_PUSH = ROOT / "scripts" / "arm_push.yaml"  # keys at 0, 0.5 and 1.5 s


def run(*args: str) -> Result:
    return CliRunner().invoke(cli, [str(a) for a in args])


def one_error(result: Result) -> str:
    """The single ``error:`` line of a failed command (exit status 1, no traceback)."""
    assert result.exit_code == 1, result.output
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), result.stderr
    return lines[0][len("error: ") :]


def test_rig_from_bvh_writes_a_rig_that_validates(tmp_path) -> None:
    src = tmp_path / "walk.bvh"
    src.write_text(make_bvh("mixamo65", "ZYX"))
    out = tmp_path / "walk.yaml"
    result = run("rig", "from-bvh", src, "-o", out)
    assert result.exit_code == 0, result.output
    assert "assuming centimetres (25–300 units across; --scale 0.01)" in result.stderr
    assert "wrote" in result.stdout and "65 bones" in result.stdout
    assert len(load_rig(out).bones) == 65
    assert run("validate", out).exit_code == 0
    assert "exists: pass --force" in one_error(run("rig", "from-bvh", src, "-o", out))
    assert run("rig", "from-bvh", src, "-o", out, "--force", "--frame", "1").exit_code == 0
    result = run("rig", "from-bvh", src, "-o", out, "--force", "--scale", "0.02")
    assert result.exit_code == 0 and "assuming" not in result.stderr


def test_rig_from_bvh_frame_out_of_range(tmp_path) -> None:
    src = tmp_path / "walk.bvh"
    src.write_text(make_bvh("simple19", "XYZ", frames=3))
    message = one_error(run("rig", "from-bvh", src, "-o", tmp_path / "r.yaml", "--frame", "3"))
    assert message == f"{src}: --frame: expected a frame index from 0 to 2, got 3 (Frames: 3)"
    assert not (tmp_path / "r.yaml").exists()


@pytest.mark.parametrize(("name", "edit", "line", "message"), BAD, ids=[b[0] for b in BAD])
def test_rig_from_bad_bvh_is_one_error_line(tmp_path, name, edit, line, message) -> None:
    src = tmp_path / "bad.bvh"
    src.write_bytes(edit(SMALL).encode())
    assert one_error(run("rig", "from-bvh", src, "-o", tmp_path / "r.yaml")) == (
        f"{src}:{line}: {message}"
    )


def test_convert_keys_match_pose(tmp_path) -> None:
    """One frame per key; the BVH's FK puts each joint at keyframes.json's head (to within
    the simulation's joint gaps, which a rigid BVH skeleton cannot carry)."""
    out = tmp_path / "arm.bvh"
    result = run("convert", ARM_PUSH, "--rig", DOLL, "-o", out, "--scale", "100")
    assert result.exit_code == 0, result.output
    assert run("pose", DOLL, ARM_PUSH, "-o", tmp_path / "pose", "--no-trace").exit_code == 0
    _, keys = read_keyframes(tmp_path / "pose" / "keyframes.json")
    names, _, positions = independent_fk(out.read_text())
    size = Skeleton.from_spec(load_rig(DOLL)).size
    assert len(keys) == positions.shape[0] == 3
    for f, key in enumerate(keys):
        heads = np.array([key.bones[n].head for n in names])
        assert np.abs(positions[f] / 100.0 - heads).max() < 1e-4 * size
    assert "Frame Time: 0.03333333333" in out.read_text()


def test_convert_samples_the_motion_at_fps(tmp_path) -> None:
    keys_bvh, motion_bvh = tmp_path / "keys.bvh", tmp_path / "motion.bvh"
    assert run("convert", ARM_PUSH, "--rig", DOLL, "-o", keys_bvh, "--order", "zyx").exit_code == 0
    result = run("convert", ARM_PUSH, "--rig", DOLL, "-o", motion_bvh, "--fps", "20", "--order",
                 "ZYX")  # fmt: skip
    assert result.exit_code == 0, result.output
    motion, keys = bvh_package.Bvh(motion_bvh.read_text()), bvh_package.Bvh(keys_bvh.read_text())
    assert motion.nframes == math.floor(1.5 * 20) + 1
    assert abs(motion.frame_time - 0.05) < 1e-12
    assert motion.joint_channels("spine") == ["Zrotation", "Yrotation", "Xrotation"]
    # Frames 0, 10 and 30 fall on the keys' times (0, 0.5, 1.5 s): the same pose.
    for frame, key in ((0, 0), (10, 1), (30, 2)):
        a = np.array(motion.frames[frame], dtype=float)
        b = np.array(keys.frames[key], dtype=float)
        np.testing.assert_allclose(a, b, atol=1e-5)


def test_convert_refusals(tmp_path) -> None:
    out = tmp_path / "x.bvh"
    session = tmp_path / "take.mcap"
    session.write_bytes(b"")  # sessions are converted too; an empty one is refused
    message = one_error(run("convert", session, "--rig", DOLL, "-o", out))
    assert message.startswith(
        f"{session}: expected a complete MCAP file, got a truncated or corrupt one"
    )
    out.write_text("keep")
    message = one_error(run("convert", ARM_PUSH, "--rig", DOLL, "-o", out))
    assert message == f"{out} exists: pass --force to overwrite" and out.read_text() == "keep"
    assert run("convert", ARM_PUSH, "--rig", DOLL, "-o", out, "--force").exit_code == 0
    assert out.read_text().startswith("HIERARCHY\n")
    script = tmp_path / "nokeys.yaml"
    script.write_text("actions:\n  - wait: 0.05\n")
    message = one_error(run("convert", script, "--rig", DOLL, "-o", tmp_path / "n.bvh"))
    assert message == f"{script}: expected at least one 'key' action (or --fps), got none"
    assert (
        run("convert", script, "--rig", DOLL, "-o", tmp_path / "n.bvh", "--fps", "40").exit_code
        == 0
    )
    assert bvh_package.Bvh((tmp_path / "n.bvh").read_text()).nframes == 3


def test_convert_reports_script_errors_in_one_line(tmp_path) -> None:
    script = tmp_path / "bad.yaml"
    script.write_text("actions:\n  - push: {bone: spin, force: [0, 1, 0], duration: 0.1}\n")
    message = one_error(run("convert", script, "--rig", DOLL, "-o", tmp_path / "b.bvh"))
    assert message.startswith(f"{script}:2: ") and "spine" in message
    assert not (tmp_path / "b.bvh").exists()


def test_help_lists_the_commands() -> None:
    result = run("--help")
    assert "rig" in result.output and "convert" in result.output
    assert "from-bvh" in run("rig", "--help").output
