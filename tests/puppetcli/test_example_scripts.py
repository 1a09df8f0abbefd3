"""Every example script runs through `puppetcli pose` and passes its own expectations."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml
from bvh import Bvh
from click.testing import CliRunner

from puppetcli.cli import cli
from puppetcli.mcap.trace import read_trace
from puppetcli.run.keyframes import read_keyframes

ROOT = Path(__file__).resolve().parents[2]
DOLL_SCRIPTS = ["wave", "head_twist", "kneel", "hand_on_table", "free_push", "arm_push"]


@pytest.mark.parametrize("name", DOLL_SCRIPTS)
def test_example_script_passes_its_expectations(name, tmp_path):
    script = ROOT / "scripts" / f"{name}.yaml"
    result = CliRunner().invoke(
        cli, ["pose", str(ROOT / "rigs/doll.yaml"), str(script), "-o", str(tmp_path)]
    )
    assert result.exit_code == 0, result.output
    actions = yaml.safe_load(script.read_text())["actions"]
    expects = sum("expect" in a for a in actions)
    keys = sum("key" in a for a in actions)
    assert keys >= 3
    if expects:
        assert f"expectations: {expects} of {expects} passed" in result.stdout
    _, taken = read_keyframes(tmp_path / "keyframes.json")
    assert len(taken) == keys
    motion = Bvh((tmp_path / "keyframes.bvh").read_text())  # an independent parser
    assert motion.nframes == keys
    assert set(motion.get_joints_names()) == set(taken[0].bones)
    assert len(list((tmp_path / "keys").glob("*.png"))) == keys
    trace = read_trace(tmp_path / "trace.mcap")
    assert len(trace["/puppet/keyframe"]) == keys
    if name != "arm_push":  # scripts that use the pointer record it
        assert len(trace["/device/pose"]) == len(trace["/puppet/joints"])


def test_every_script_file_is_exercised():
    on_disk = {p.stem for p in (ROOT / "scripts").glob("*.yaml")}
    # identify_forearm: tests/puppetcli/feel/test_identify.py
    assert on_disk == set(DOLL_SCRIPTS) | {"creep", "identify_forearm"}
