"""The paper's experiment through `puppetcli pose`, checked in the trace and the keys."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from click.testing import CliRunner
from paper_experiment import T_END, T_LOAD, recursion

from puppetcli.cli import cli
from puppetcli.mcap.trace import read_trace
from puppetcli.run.keyframes import read_keyframes
from solver import quat

ROOT = Path(__file__).resolve().parents[2]


def test_creep_script_matches_the_exact_recursion_in_trace_and_keys(tmp_path):
    result = CliRunner().invoke(
        cli,
        [
            "pose",
            str(ROOT / "rigs/one_bone.yaml"),
            str(ROOT / "scripts/creep.yaml"),
            "-o",
            str(tmp_path),
        ],
    )
    assert result.exit_code == 0, result.output
    h = 0.02
    expected = recursion(h)
    joints = read_trace(tmp_path / "trace.mcap")["/puppet/joints"]
    assert len(joints) == len(expected) == round(T_END / h)
    times = np.array([ns for ns, _ in joints]) * 1e-9
    angles = np.array([msg["joints"]["bone"]["rotation"][2] for _, msg in joints])
    # whole ns: measured 8.9e-16 s
    assert np.allclose(times, h * np.arange(1, len(expected) + 1), rtol=0.0, atol=5e-15)
    # measured 6.1e-16 rad (the trace's JSON keeps every bit); 1e-12: rounding headroom
    assert np.max(np.abs(angles - expected)) < 1e-12
    rig, keys = read_keyframes(tmp_path / "keyframes.json")
    assert rig == "one_bone" and [k.label for k in keys] == ["rest", "loaded", "recovered"]
    loaded = quat.log(keys[1].bones["bone"].local)[2]
    recovered = quat.log(keys[2].bones["bone"].local)[2]
    assert abs(loaded - expected[round(T_LOAD / h) - 1]) < 1e-12  # measured 1.7e-16
    assert abs(recovered - expected[-1]) < 1e-12  # measured 6.1e-16
    assert 0.0 < recovered < loaded  # partial spring-back, a residual remains
