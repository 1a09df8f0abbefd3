"""What commands report: ``--json`` documents checked against the files the same run wrote
(read back by independent parsers), key times on the step grid, validate's solver against the
solver the steps really used, and shell completion."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import bvh as bvh_package
import cv2
import pytest
import yaml
from click.testing import CliRunner
from mcap.reader import make_reader

from puppetcli.cli import cli
from puppetcli.rig.load import load_rig, rig_from_text
from solver.engine import Engine, NumpyStepper
from solver.model import build_model

ROOT = Path(__file__).resolve().parents[2]
DOLL, WAVE = ROOT / "rigs" / "doll.yaml", ROOT / "scripts" / "wave.yaml"


def run_json(*args: object, code: int = 0) -> dict:
    result = CliRunner().invoke(cli, [str(a) for a in args] + ["--json"])
    assert result.exit_code == code, (result.stdout, result.stderr)
    return json.loads(result.stdout)  # exactly one document: json.loads refuses trailing text


@pytest.fixture(scope="module")
def posed(tmp_path_factory) -> tuple[Path, dict]:
    out = tmp_path_factory.mktemp("posed")
    return out, run_json("pose", DOLL, WAVE, "-o", out, "--force")


def test_pose_json_matches_what_it_wrote(posed) -> None:
    out, doc = posed
    keys = json.loads((out / "keyframes.json").read_text())["keys"]
    assert doc["ok"] is True and doc["error"] is None
    assert [(k["label"], k["time"]) for k in doc["keys"]] == [(k["label"], k["time"]) for k in keys]
    assert doc["steps"] == round(doc["simulated"] / doc["h"]) == 700
    assert [e["passed"] for e in doc["expectations"]] == [True, True, True]
    assert sorted(Path(p).name for p in doc["outputs"]) == sorted(
        ["keyframes.json", "keyframes.bvh", "sheet.png", "keys", "trace.mcap"]
    )


def test_key_times_are_on_the_step_grid(posed) -> None:
    """wave.yaml's keys fall at 0, 2 and 3.5 s; the text says 2.0, not 1.9999999999999793."""
    out, _ = posed
    text = (out / "keyframes.json").read_text()
    times = [k["time"] for k in json.loads(text)["keys"]]
    assert times == [0.0, 2.0, 3.5]
    assert '"time": 2.0,' in text


def test_convert_render_record_validate_json(tmp_path: Path, posed) -> None:
    out, _ = posed
    bvh_doc = run_json("convert", WAVE, "--rig", DOLL, "-o", tmp_path / "w.bvh", "--fps", "50")
    with (tmp_path / "w.bvh").open() as f:
        mocap = bvh_package.Bvh(f.read())
    assert bvh_doc["frames"] == mocap.nframes and bvh_doc["fps"] == 50.0
    assert abs(mocap.frame_time - 0.02) < 1e-12

    sheet = run_json("render", out / "keyframes.json", "--rig", DOLL, "-o", tmp_path / "s.png",
                     "--size", "64x48")  # fmt: skip
    img = cv2.imread(str(tmp_path / "s.png"))
    s = sheet["sheet"]
    assert (s["panels"], img.shape[:2]) == (3, (48 * s["rows"], 64 * s["cols"]))

    rec = run_json("record", DOLL, WAVE, "-o", tmp_path / "w.mcap")
    with (tmp_path / "w.mcap").open("rb") as f:
        ticks = sum(1 for _ in make_reader(f).iter_messages(topics=["/spidar/counts"]))
    assert rec["ticks"] == ticks and rec["device"] == "SpidarG6X3R"

    val = run_json("validate", DOLL)
    assert val["bones"] == len(yaml.safe_load(DOLL.read_text())["bones"])


def test_a_failure_with_json_is_one_document_and_one_line(tmp_path: Path) -> None:
    result = CliRunner().invoke(cli, ["validate", str(tmp_path / "no.yaml"), "--json"])
    assert result.exit_code == 2
    doc = json.loads(result.stdout)
    assert doc == {"ok": False, "error": doc["error"], "exit_code": 2}
    assert result.stderr == f"error: {doc['error']}\n"


def test_stress_json(tmp_path: Path) -> None:
    doc = run_json("stress", "--case", "spin")
    assert doc["ok"] is True and [c["name"] for c in doc["cases"]] == ["spin"]
    assert doc["cases"][0]["nonfinite"] is False


def test_bench_json_is_one_document(monkeypatch) -> None:
    """The bench's table rows as JSON (the measurement itself is the bench's, stubbed here
    with one row so the test does not time anything)."""
    from puppetcli.bench import skips

    row = skips.SkipRow("cull_pairs", "doll", 10.0, 5.0, 2.0, 0.0, float("nan"))
    monkeypatch.setattr(skips, "measure_skips", lambda h, seconds: [row])
    doc = run_json("bench", "--skips")
    assert doc["skips"] == [{"skip": "cull_pairs", "scene": "doll", "on_steps_per_s": 10.0,
                             "off_steps_per_s": 5.0, "speedup": 2.0, "position_diff": 0.0,
                             "rotation_diff": None}]  # fmt: skip


NO_CONTACT_RIG = """\
name: hanging
root: fixed
defaults:
  shape: {type: capsule, radius: 0.03}
  joint: {kf: 30.0, df: 1.0, dd: 50.0}
bones:
  - {name: a, head: [0, 1.0, 0], tail: [0, 0.8, 0], mass: 1.0}
  - {name: b, parent: a, head: [0, 0.8, 0], tail: [0.2, 0.8, 0], mass: 1.0}
"""


SPRINGS_RIG = NO_CONTACT_RIG.replace("dd: 50.0", "plastic: false") + "solver: {integrator: bdf2}\n"


@pytest.mark.parametrize("rig", ["doll", "hanging", "springs"])
def test_validate_names_the_solver_the_steps_use(rig: str, tmp_path: Path) -> None:
    """validate's solver line, against the solver each of 200 steps reports using (the
    numpy step's for the rows; the in-place stepper's for a tree of springs under bdf2)."""
    if rig == "doll":
        spec, path = load_rig(DOLL), DOLL
    else:
        text = NO_CONTACT_RIG if rig == "hanging" else SPRINGS_RIG
        path = tmp_path / f"{rig}.yaml"
        path.write_text(text)
        spec = rig_from_text(text, str(path))
    words = run_json("validate", path)["solver"]
    model = build_model(spec)
    engine = Engine(model).stepper() if rig == "springs" else NumpyStepper(model)
    used = set()
    for _ in range(200):
        engine.advance()
        used.add(engine.report.solver)
    if rig == "doll":  # the doll stands on the ground: contact rows every step
        assert used == {"hybrid"} and words.startswith("auto: direct on steps with two-sided")
    elif rig == "hanging":  # a series damper: rows
        assert used == {"direct"} and words.startswith("direct (auto: this scene has two-sided")
    else:
        assert used == {"joint-space"} and words.startswith("joint space (a tree of")


def test_shell_completion_offers_commands_options_and_views() -> None:
    def complete(words: str, cword: int) -> list[str]:
        env = {**os.environ, "PUPPETCLI_DAEMON": "off", "COMP_WORDS": words,
               "COMP_CWORD": str(cword), "_PUPPETCLI_COMPLETE": "bash_complete"}  # fmt: skip
        out = subprocess.run([sys.executable, "-m", "puppetcli"], env=env, capture_output=True,
                             text=True, check=True).stdout  # fmt: skip
        return [line.split(",", 1)[1] for line in out.splitlines()]

    assert complete("puppetcli po", 1) == ["pose"]
    assert "--order" in complete("puppetcli pose --or", 2)
    assert complete("puppetcli pose --view ", 3) == ["front", "side", "top", "iso", "custom:"]


def test_order_is_accepted_in_any_case(tmp_path: Path) -> None:
    for order in ("xyz", "XyZ"):
        out = tmp_path / f"{order}.bvh"
        args = ["convert", str(WAVE), "--rig", str(DOLL), "-o", str(out), "--order", order]
        result = CliRunner().invoke(cli, args)
        assert result.exit_code == 0, result.stderr
    a, b = ((tmp_path / f"{o}.bvh").read_text() for o in ("xyz", "XyZ"))
    assert a == b and "Xrotation Yrotation Zrotation" in a
