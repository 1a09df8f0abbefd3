"""fit from targets: the written rig, re-measured by feel, meets each target.

Independent values: the targets themselves, re-measured by a separate ``feel`` run on the
written rig (a fresh load and simulation); the original rig for the bones left alone.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from puppetcli.cli import cli
from puppetcli.rig.load import load_rig

ROOT = Path(__file__).resolve().parents[3]
ONE_BONE = ROOT / "rigs" / "one_bone.yaml"
DOLL = ROOT / "rigs" / "doll.yaml"


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def measured(rig: Path, joint: str | None = None) -> dict:
    args = ["feel", rig, "--json"] + (["--joint", joint] if joint else [])
    result = run(*args)
    assert result.exit_code == 0, result.output
    return json.loads(result.stdout)["joints"][0]["axes"][0]["measured"]


def test_one_bone_meets_three_targets(tmp_path) -> None:
    """Retention 0.6, spring-back 2 s, effort 5 N·m: feel on the fitted rig finds them
    within 0.44 %, 0.12 % and 0.19 % (the tolerances ~5× that; the issue asks for 5 %)."""
    out = tmp_path / "fitted.yaml"
    result = run("fit", ONE_BONE, "-o", out, "--target", "retention=0.6",
                 "--target", "springback=2s", "--target", "effort=5Nm")  # fmt: skip
    assert result.exit_code == 0, result.output
    m = measured(out)
    assert m["retention"] == pytest.approx(0.6, rel=0.02)
    assert m["springback_time"] == pytest.approx(2.0, rel=6e-3)
    assert m["effort"] == pytest.approx(5.0, rel=0.01)
    assert "# fitted by `puppetcli fit`: retention 0.6 (now" in out.read_text()


def test_doll_forearm_meets_its_targets_and_the_rest_is_kept(tmp_path) -> None:
    """forearm_l: retention 0.8 and 60 N at the hand's end (0.25 m: 15 N·m), met to 1.2e-10
    and 9.9e-11 (fit's least squares converged on the rig itself); every other bone as it
    was."""
    out = tmp_path / "doll.yaml"
    result = run("fit", DOLL, "-o", out, "--target", "forearm_l.retention=0.8",
                 "--target", "forearm_l.effort=60N")  # fmt: skip
    assert result.exit_code == 0, result.output
    m = measured(out, "forearm_l")
    assert m["retention"] == pytest.approx(0.8, rel=6e-10)
    assert m["tip_force"] == pytest.approx(60.0, rel=6e-10)
    before = {b.name: b for b in load_rig(DOLL).bones}
    for bone in load_rig(out).bones:
        same = before[bone.name]
        assert np.array_equal(bone.head, same.head) and bone.shape == same.shape
        if bone.name != "forearm_l" and same.rheology is None:
            assert bone.rheology is None
        elif bone.name != "forearm_l":
            assert np.array_equal(bone.rheology.kf, same.rheology.kf)
            assert np.array_equal(bone.rheology.dd, same.rheology.dd)
            assert bone.rheology.yield_torque == same.rheology.yield_torque


@pytest.mark.parametrize(
    ("target", "message"),
    [
        ("stiffness=3", "expected one of retention, springback, effort, yield, got 'stiffness'"),
        ("retention=1.5", "retention: expected a share between 0 and 1, got 'retention=1.5'"),
        ("springback=2h", "springback: expected a unit among 's', 'ms', got 'h'"),
        ("elbow.retention=0.5", "expected a joint of the rig, got 'elbow'"),
        ("effort", "expected [JOINT.]NAME=VALUE[UNIT], got 'effort'"),
    ],
)
def test_bad_targets_are_usage_errors(tmp_path, target, message) -> None:
    result = run("fit", DOLL, "-o", tmp_path / "x.yaml", "--target", target)
    assert result.exit_code == 2
    (line,) = result.stderr.strip().splitlines()
    assert message in line


def test_an_unreachable_target_is_one_error_line(tmp_path) -> None:
    """A joint that never yields (1,000 N·m against ~9 N·m of bending) and springs back in
    10 ms keeps nothing: retention 0.5 is out of reach."""
    result = run("fit", ONE_BONE, "-o", tmp_path / "x.yaml", "--target", "retention=0.5",
                 "--target", "springback=10ms", "--target", "yield=1000Nm")  # fmt: skip
    assert result.exit_code == 1
    (line,) = result.stderr.strip().splitlines()
    assert line.startswith("error: bone: expected targets the three-element joint can meet")
    assert not (tmp_path / "x.yaml").exists()
