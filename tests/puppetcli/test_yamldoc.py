"""YAML documents: libyaml and pure-Python pyyaml read every shipped file alike, and a
document too deep for either ends in one line, not a crash."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from puppetcli import yamldoc
from puppetcli.rig.load import load_rig
from puppetcli.script.load import load_script
from solver.errors import PuppetError

ROOT = Path(__file__).resolve().parents[2]
RIGS = sorted((ROOT / "rigs").glob("*.yaml"))
SCRIPTS = sorted((ROOT / "scripts").glob("*.yaml"))


def _nodes(node: yaml.Node) -> list[tuple]:
    """Every node as (kind, tag, line, column, value of a scalar), depth first."""
    out = [(type(node).__name__, node.tag, node.start_mark.line, node.start_mark.column)]
    if isinstance(node, yaml.ScalarNode):
        return [(*out[0], node.value)]
    children = node.value if isinstance(node, yaml.SequenceNode) else [
        n for pair in node.value for n in pair]  # fmt: skip
    return out + [item for child in children for item in _nodes(child)]


@pytest.mark.parametrize("path", RIGS + SCRIPTS, ids=lambda p: p.name)
def test_libyaml_composes_what_pyyaml_composes(path):
    text = path.read_text(encoding="utf-8")
    assert yamldoc._shallow(text)  # so the fast loader reads it
    fast = yaml.compose(text, Loader=yamldoc.FAST_LOADER)
    assert yamldoc.FAST_LOADER is not yaml.SafeLoader  # the C one is installed here
    assert _nodes(fast) == _nodes(yaml.compose(text, Loader=yaml.SafeLoader))


def _outcomes() -> list[str]:
    """Each rig, and each script on each rig: what loading gives, or its error line."""
    out = []
    for rig_path in RIGS:
        rig = load_rig(rig_path)
        out.append(repr(rig))
        for script in SCRIPTS:
            try:
                out.append(repr(load_script(script, rig)))
            except PuppetError as exc:
                out.append(str(exc))
    return out


def test_rigs_and_scripts_load_the_same_either_way(monkeypatch):
    fast = _outcomes()
    monkeypatch.setattr(yamldoc, "FAST_DEPTH", 0)  # every document through pure Python
    assert _outcomes() == fast


@pytest.mark.parametrize("text", [
    "a: " + "[" * 100_000 + "]" * 100_000,  # flow: crashes libyaml's composer (measured)
    "a: " + "- " * 100_000 + "1",  # block sequences on one line
    "".join(" " * i + f"k{i}:\n" for i in range(3000)) + " " * 3000 + "v: 1\n",  # indentation
], ids=["flow", "dashes", "indented"])  # fmt: skip
def test_a_deep_document_is_one_line_of_error(tmp_path, text):
    path = tmp_path / "deep.yaml"
    path.write_text(text)
    result = subprocess.run(
        [sys.executable, "-m", "puppetcli", "validate", str(path)], capture_output=True, text=True
    )
    assert result.returncode == 1, result.stderr[-500:]
    assert result.stderr.startswith(f"error: {path}") and result.stderr.count("\n") == 1
