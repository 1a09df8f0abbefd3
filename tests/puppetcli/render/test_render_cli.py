"""``puppetcli render``: outputs, --force, and one ``error: …`` line for every mistake."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from click.testing import CliRunner, Result
from test_render_fixtures import DOLL, doll, keys
from test_render_trace import write_trace

from puppetcli.cli import cli
from puppetcli.run.keyframes import write_keyframes


def run(*args: str) -> Result:
    return CliRunner().invoke(cli, ["render", *args])


@pytest.fixture
def keyfile(tmp_path: Path) -> Path:
    _, skel = doll()
    path = tmp_path / "keyframes.json"
    write_keyframes(path, "doll", keys(skel, 5))
    return path


def one_error(result: Result) -> str:
    """The single stderr line of a failed command, which must start with ``error: ``."""
    assert result.exit_code == 1, result.output
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), result.stderr
    return lines[0]


def usage_error(result: Result) -> str:
    """The single stderr line of a command called wrongly (status 2)."""
    assert result.exit_code == 2, result.output
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), result.stderr
    assert lines[0].endswith("(see 'cli render --help')"), lines[0]
    return lines[0]


def test_sheet_of_keyframes(tmp_path: Path, keyfile: Path) -> None:
    out = tmp_path / "sheets" / "sheet.png"  # a missing folder is created
    result = run(str(keyfile), "--rig", str(DOLL), "-o", str(out), "--cols", "2",
                 "--view", "custom:30,20,3.5", "--size", "80x60")  # fmt: skip
    assert result.exit_code == 0, result.output
    assert result.stdout == f"{out}: 5 panels, 2 × 3, custom view, 80x60 px each\n"
    assert cv2.imread(str(out)).shape == (3 * 60, 2 * 80, 3)


def test_same_input_same_bytes(tmp_path: Path, keyfile: Path) -> None:
    for name in ("a.png", "b.png"):
        assert run(str(keyfile), "--rig", str(DOLL), "-o", str(tmp_path / name),
                   "--size", "64x64").exit_code == 0  # fmt: skip
    assert (tmp_path / "a.png").read_bytes() == (tmp_path / "b.png").read_bytes()


def test_force(tmp_path: Path, keyfile: Path) -> None:
    out = tmp_path / "sheet.png"
    out.write_bytes(b"keep me")
    args = [str(keyfile), "--rig", str(DOLL), "-o", str(out), "--size", "32x32"]
    assert one_error(run(*args)) == f"error: {out} exists: pass --force to overwrite"
    assert out.read_bytes() == b"keep me"
    result = run(*args, "--force")
    assert result.exit_code == 0, result.output
    assert cv2.imread(str(out)).shape == (2 * 32, 4 * 32, 3)  # 5 keys: 4 + 1 panels


def test_sheet_of_a_trace(tmp_path: Path) -> None:
    _, skel = doll()
    write_trace(tmp_path / "trace.mcap", skel, keys(skel, 5))
    out = tmp_path / "s.png"
    result = run(str(tmp_path / "trace.mcap"), "--rig", str(DOLL), "-o", str(out),
                 "--size", "40x40", "--view", "top")  # fmt: skip
    assert result.exit_code == 0, result.output
    assert cv2.imread(str(out)).shape == (40, 3 * 40, 3)  # key events at keys 1, 3, 5


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--view", "back"], "'--view': expected one of front, side, top, iso or custom:"),
        (["--view", "custom:1"], "'--view': expected one of front, side, top, iso or custom:"),
        (["--size", "big"], "'--size': expected WIDTHxHEIGHT in pixels (e.g. 480x480), got 'big'"),
        (["--size", "4x4"], "'--size': expected each side in 16 … 8192 px, got 4x4"),
        (["--cols", "0"], "'--cols': 0 is not in the range 1<=x<=100"),
        (["--fps", "0", "--video", "v.mp4"], "'--fps': 0.0 is not in the range 1.0<=x<=240.0"),
        (["--fps", "nan", "--video", "v.mp4"], "'--fps': 'nan' is not a finite number in the"),
        (["--video", "v.mp4"], "'--video': expected a trace or session .mcap INPUT"),
        (["-o", "sheet.jpg"], "'-o': expected a .png file name, got 'sheet.jpg'"),
    ],
)
def test_option_errors(tmp_path: Path, keyfile: Path, args: list[str], message: str) -> None:
    """A bad option is a usage error (status 2), found before any file is read or written."""
    full = [str(keyfile), "--rig", str(DOLL), *args]
    if "-o" not in args:
        full += ["-o", str(tmp_path / "s.png")]
    assert usage_error(run(*full)).startswith(f"error: Invalid value for {message}")
    assert not (tmp_path / "s.png").exists()


def test_input_errors(tmp_path: Path, keyfile: Path) -> None:
    """A missing input or option is a usage error (status 2); a bad file's content, status 1."""
    out = ["-o", str(tmp_path / "s.png")]
    missing = tmp_path / "nope.json"
    assert usage_error(run(str(missing), "--rig", str(DOLL), *out)).startswith(
        f"error: Invalid value for 'INPUT': File '{missing}' does not exist."
    )
    bad = tmp_path / "bad.json"
    bad.write_text("{")
    assert f"error: {bad}: expected JSON" in one_error(run(str(bad), "--rig", str(DOLL), *out))
    assert usage_error(run(str(keyfile), *out)).startswith("error: missing option '--rig': ")
    assert usage_error(run(str(keyfile), "--rig", str(tmp_path / "no.yaml"), *out)).startswith(
        f"error: Invalid value for '--rig': File '{tmp_path / 'no.yaml'}' does not exist."
    )
    text = tmp_path / "pose.txt"
    text.write_text("x")
    assert (
        "expected keyframes.json, a .bvh or .glb file, a trace .mcap or a rig .yaml, got a .txt"
        in usage_error(run(str(text), "--rig", str(DOLL), *out))
    )
    corrupt = tmp_path / "trace.mcap"
    corrupt.write_bytes(b"\x89MCAP0\r\n" + b"\0" * 40)
    assert "not a readable MCAP trace" in one_error(run(str(corrupt), "--rig", str(DOLL), *out))
    assert usage_error(run(str(keyfile), "--rig", str(DOLL))).startswith(
        "error: nothing to write: give -o SHEET.png and/or --video OUT.mp4"
    )


def test_keys_of_another_rig(tmp_path: Path, keyfile: Path) -> None:
    one_bone = DOLL.parent / "one_bone.yaml"
    line = one_error(run(str(keyfile), "--rig", str(one_bone), "-o", str(tmp_path / "s.png")))
    assert "expected a pose of every bone of the rig, got no bone" in line


def test_bvh_input(tmp_path: Path) -> None:
    """Frames written from keys (in cm) render as those keys' poses, labelled by frame index
    as ``rig from-bvh --frame`` counts them."""
    from puppetcli.bvh.write import write_keys_bvh
    from puppetcli.render.inputs import key_poses
    from puppetcli.render.picture import poses_from_keys

    path = tmp_path / "motion.bvh"
    spec, skel = doll()
    ks = keys(skel, 4)
    write_keys_bvh(path, skel, ks, scale=100.0, fps=10.0)
    got = key_poses(path, "bvh", skel, spec)
    expected = poses_from_keys(skel, ks)
    assert [p.label for p in got] == ["frame 0", "frame 1", "frame 2", "frame 3"]
    assert [p.time for p in got] == pytest.approx([0.0, 0.1, 0.2, 0.3])
    for a, b in zip(got, expected, strict=True):
        assert np.allclose(a.head, b.head, atol=1e-6) and np.allclose(a.tail, b.tail, atol=1e-6)
        assert np.allclose(np.abs(np.sum(a.rot * b.rot, axis=1)), 1.0, atol=1e-9)
    result = run(str(path), "--rig", str(DOLL), "-o", str(tmp_path / "s.png"), "--size", "32x32")
    assert result.exit_code == 0, result.output
    assert cv2.imread(str(tmp_path / "s.png")).shape == (32, 4 * 32, 3)


def test_listed_in_help() -> None:
    result = CliRunner().invoke(cli, ["--help"])
    assert "render" in result.output and "contact sheet" in result.output
    assert CliRunner().invoke(cli, ["render", "--help"]).exit_code == 0
