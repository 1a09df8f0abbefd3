"""The official Khronos glTF validator (npm ``gltf-validator``), run through Node.js.

CI installs it with ``npm install --prefix tests/node gltf-validator@VERSION``
(see .ci/run); elsewhere the tests that need it are skipped when Node.js or the
package is missing, and in CI (the ``CI`` variable set) that is a failure.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[3]
MODULES = ROOT / "tests" / "node" / "node_modules"
SCRIPT = Path(__file__).with_name("validate.js")


def validate(*paths: Path) -> dict[str, dict]:
    """The validator's ``issues`` object (numErrors, numWarnings, messages…) per file."""
    node = shutil.which("node")
    if node is None or not (MODULES / "gltf-validator").is_dir():
        why = "needs Node.js and the gltf-validator package in tests/node (see .ci/run)"
        if os.environ.get("CI"):
            pytest.fail(why)
        pytest.skip(why)
    env = {**os.environ, "NODE_PATH": str(MODULES)}
    done = subprocess.run(
        [node, str(SCRIPT), *map(str, paths)], capture_output=True, text=True, env=env, check=False
    )
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


def problems(report: dict) -> list[str]:
    """Every error, warning and info the validator raised (severity 0, 1, 2), as text."""
    return [
        f"{m['code']} at {m.get('pointer', '?')}: {m['message']}"
        for m in report["messages"]
        if m["severity"] <= 2
    ]
