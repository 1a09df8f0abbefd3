"""CLI tests: one-line errors for bad rigs and scripts, outputs, failed runs, summaries.

Every error case edits one line of a small valid rig or script and checks that
the command ends with exit status 1 and exactly one ``error: FILE:LINE: PATH:
expected …, got …`` line on stderr, the line being the one edited (YAML syntax
errors: the line PyYAML itself reports).
"""

from __future__ import annotations

import importlib.metadata
import json
import math
import re
from dataclasses import dataclass
from pathlib import Path

import pytest
import yaml
from click.testing import CliRunner, Result
from mcap.reader import make_reader

from puppetcli.cli import cli

ROOT = Path(__file__).resolve().parents[2]
DOLL = ROOT / "rigs" / "doll.yaml"
ONE_BONE = ROOT / "rigs" / "one_bone.yaml"
OUTPUTS = ("keyframes.json", "keyframes.bvh", "trace.mcap")

RIG = """\
name: tiny
root: fixed
defaults:
  shape: {type: capsule, radius: 0.04}
  joint: {kf: 50.0, df: 2.0, dd: 100.0}
bones:
  - name: hips
    head: [0, 1.0, 0]
    tail: [0, 1.1, 0]
    shape: {type: box, size: [0.3, 0.1, 0.15]}
    mass: 2.0
  - name: spine
    parent: hips
    head: [0, 1.1, 0]
    tail: [0, 1.4, 0]
    mass: 1.5
    joint: {kf: 80.0, df: 3.0}
  - name: neck
    parent: spine
    head: [0, 1.4, 0]
    tail: [0, 1.6, 0]
    density: 900
"""

SCRIPT = """\
actions:
  - key: rest
  - push: {bone: spine, torque: [0, 0, 1.0], duration: 0.1}
  - wait: 0.1
  - key: done
"""

# one_bone.yaml: a 1e6 N·m torque on a 0.1 kg·m² body spins it far beyond any
# speed limit within the first step of the push.
BLOW_UP = """\
actions:
  - key: rest
  - wait: 0.1
  - key: before
  - push: {bone: bone, torque: [0, 0, 1.0e+6], duration: 0.5}
  - key: after
"""


def line_of(text: str, marker: str) -> int:
    """The 1-based number of the one line of ``text`` that contains ``marker``."""
    hits = [n for n, line in enumerate(text.splitlines(), 1) if marker in line]
    assert len(hits) == 1, f"{marker!r} is on lines {hits}"
    return hits[0]


@dataclass(frozen=True)
class Case:
    """A one-place edit of a valid file and the error it must produce."""

    id: str
    old: str
    new: str
    marker: str  # text on the line the error must name, in the edited file
    path: str | None  # YAML path in the message; None for a YAML syntax error
    words: tuple[str, ...] = ()

    def apply(self, base: str) -> str:
        assert base.count(self.old) == 1, self.old
        return base.replace(self.old, self.new)


def cases(*items: Case) -> list:
    return [pytest.param(c, id=c.id) for c in items]


RIG_CASES = cases(
    Case("unknown_key", "mass: 1.5", "mas: 1.5", "mas: 1.5", "bones[1].mas",
         ("got 'mas'", "did you mean 'mass'?")),
    Case("unknown_top_key", "root: fixed", "roots: fixed", "roots:", "roots",
         ("got 'roots'", "did you mean 'root'?")),
    Case("unknown_parent", "parent: hips", "parent: hipz", "parent: hipz", "bones[1].parent",
         ("got 'hipz'", "did you mean 'hips'?")),
    Case("cycle", "parent: hips", "parent: neck", "parent: neck", "bones[1].parent",
         ("cycle", "spine", "neck")),
    Case("duplicate_bone", "- name: neck", "- name: spine  # again", "# again", "bones[2].name",
         ("unique", "'spine' again", f"first at line {line_of(RIG, 'name: spine')}")),
    Case("duplicate_prop", "density: 900\n",
         "density: 900\nprops:\n  - {name: hips, shape: {type: sphere, radius: 0.1}}\n",
         "{name: hips", "props[0].name", ("'hips'",)),
    Case("second_root", "    parent: spine\n", "", "- name: neck", "bones[2]",
         ("second root", "'neck'", "'hips'")),
    Case("zero_mass", "mass: 1.5", "mass: 0", "mass: 0", "bones[1].mass",
         ("positive", "got 0")),
    Case("negative_mass", "mass: 1.5", "mass: -2", "mass: -2", "bones[1].mass",
         ("positive", "got -2")),
    Case("zero_density", "density: 900", "density: 0", "density:", "bones[2].density",
         ("positive", "got 0")),
    Case("zero_box_size", "[0.3, 0.1, 0.15]", "[0.3, 0, 0.15]", "size:",
         "bones[0].shape.size[1]", ("positive", "got 0")),
    Case("negative_radius", "radius: 0.04", "radius: -0.04", "radius:",
         "defaults.shape.radius", ("positive", "got -0.04")),
    Case("negative_coefficient", "kf: 80.0", "kf: -1", "kf: -1", "bones[1].joint.kf",
         ("non-negative", "got -1")),
    Case("nan_coefficient", "df: 3.0", "df: .nan", "df: .nan", "bones[1].joint.df",
         ("finite", "got .nan")),
    Case("inf_coefficient", "dd: 100.0", "dd: .inf", "dd: .inf", "defaults.joint.dd",
         ("finite", "got .inf")),
    Case("two_number_vector", "tail: [0, 1.4, 0]", "tail: [0, 1.4]", "tail: [0, 1.4]",
         "bones[1].tail", ("3 numbers", "2 items")),
    Case("two_number_coefficient", "kf: 80.0", "kf: [80, 90]", "kf: [80", "bones[1].joint.kf",
         ("3 numbers", "2 items")),
    Case("yaml_syntax", "mass: 1.5", "mass: 1.5: x", "mass: 1.5: x", None,
         ("mapping values are not allowed here",)),
)  # fmt: skip

POSE_RIG_IDS = {"unknown_parent", "cycle", "nan_coefficient", "two_number_vector", "yaml_syntax"}
POSE_RIG_CASES = [p for p in RIG_CASES if p.values[0].id in POSE_RIG_IDS]

SCRIPT_CASES = cases(
    Case("unknown_bone", "bone: spine", "bone: spin", "bone: spin", "actions[1].push.bone",
         ("got 'spin'", "did you mean 'spine'?")),
    Case("unknown_action", "- push:", "- pussh:", "pussh", "actions[1].pussh",
         ("action name", "got 'pussh'", "did you mean 'push'?")),
    Case("unknown_top_key", "actions:\n", "gravty: false\nactions:\n", "gravty", "gravty",
         ("got 'gravty'", "did you mean 'gravity'?")),
    Case("negative_duration", "duration: 0.1}", "duration: -0.1}", "push:",
         "actions[1].push.duration", ("positive", "got -0.1")),
    Case("zero_duration", "duration: 0.1}", "duration: 0}", "push:",
         "actions[1].push.duration", ("positive", "got 0")),
    Case("zero_wait", "wait: 0.1", "wait: 0", "wait: 0", "actions[2].wait",
         ("positive", "got 0")),
    Case("two_action_names", "  - wait: 0.1\n", "  - wait: 0.1\n    key: extra\n", "- wait",
         "actions[2]", ("one action name", "2 names", "wait", "key")),
    Case("two_number_vector", "torque: [0, 0, 1.0]", "torque: [0, 1.0]", "push:",
         "actions[1].push.torque", ("3 numbers", "2 items")),
    Case("nan_in_vector", "torque: [0, 0, 1.0]", "torque: [0, .nan, 1.0]", "push:",
         "actions[1].push.torque[1]", ("finite", "got .nan")),
    Case("unknown_action_key", "duration: 0.1}", "duraton: 0.1}", "push:",
         "actions[1].push.duraton", ("got 'duraton'", "did you mean 'duration'?")),
    Case("yaml_syntax", "wait: 0.1", "wait: 0.1: x", "wait: 0.1: x", None,
         ("mapping values are not allowed here",)),
)  # fmt: skip


# -- helpers ------------------------------------------------------------------------------


def invoke(*args: object) -> Result:
    return CliRunner().invoke(cli, [str(a) for a in args])


def write(directory: Path, name: str, text: str) -> Path:
    path = directory / name
    path.write_text(text, encoding="utf-8")
    return path


def assert_one_error(result: Result, prefix: str, words: tuple[str, ...] = ()) -> str:
    """Exit 1, no traceback, exactly one stderr line starting with ``prefix``, holding ``words``."""
    assert result.exit_code == 1, result.output
    assert isinstance(result.exception, SystemExit), result.exception  # nothing uncaught
    assert "Traceback" not in result.output
    lines = result.stderr.splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("error: ")
    assert lines[0].startswith(prefix), lines[0]
    for word in words:
        assert word in lines[0], (word, lines[0])
    return lines[0]


def assert_case_error(result: Result, case: Case, path: Path, text: str) -> None:
    """The one error line names ``path``, the edited line, the YAML path and the case's words."""
    line = line_of(text, case.marker)
    if case.path is None:
        with pytest.raises(yaml.MarkedYAMLError) as info:  # PyYAML's own verdict
            yaml.safe_load(text)
        assert info.value.problem_mark.line + 1 == line
        assert_one_error(result, f"error: {path}:{line}: YAML syntax error: ", case.words)
    else:
        prefix = f"error: {path}:{line}: {case.path}: expected "
        assert_one_error(result, prefix, (", got ", *case.words))


def hidden_files(directory: Path) -> list[str]:
    return sorted(p.name for p in directory.iterdir() if p.name.startswith("."))


def snapshot(directory: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(directory.iterdir())}


def read_mcap(path: Path) -> dict[str, list[int]]:
    """Log times (ns) by topic; every message is read with CRCs checked and decoded as JSON."""
    times: dict[str, list[int]] = {}
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        expected = reader.get_summary().statistics.message_count
        for _schema, channel, message in reader.iter_messages(log_time_order=True):
            assert channel.message_encoding == "json"
            assert isinstance(json.loads(message.data), dict)
            times.setdefault(channel.topic, []).append(message.log_time)
    assert sum(map(len, times.values())) == expected
    return times


def read_keys(path: Path) -> list[dict]:
    return json.loads(path.read_text(encoding="utf-8"))["keys"]


def script_labels(text: str) -> list[str]:
    return [a["key"] for a in yaml.safe_load(text)["actions"] if "key" in a]


def pose(tmp_path: Path, *extra: str, rig: Path | None = None, script: str = SCRIPT) -> Result:
    """``pose RIG SCRIPT -o tmp_path/out --no-render`` (the data outputs only; pictures are
    tested in test_pose_draws_every_key); the rig defaults to RIG written into tmp_path."""
    rig = rig or write(tmp_path, "rig.yaml", RIG)
    script_path = write(tmp_path, "script.yaml", script)
    return invoke("pose", rig, script_path, "-o", tmp_path / "out", "--no-render", *extra)


def summary_numbers(stdout: str) -> tuple[int, int, float]:
    """(bones, joints, total mass) from the validate summary."""
    sizes = re.search(r"(\d+) bones, (\d+) joints", stdout)
    mass = re.search(r"mass: ([0-9.]+) kg in all", stdout)
    assert sizes and mass, stdout
    return int(sizes[1]), int(sizes[2]), float(mass[1])


# -- bad rigs and scripts -------------------------------------------------------------------


@pytest.mark.parametrize("case", RIG_CASES)
def test_validate_reports_bad_rig_on_one_line(tmp_path, case):
    text = case.apply(RIG)
    rig = write(tmp_path, "rig.yaml", text)
    assert_case_error(invoke("validate", rig), case, rig, text)


@pytest.mark.parametrize("case", POSE_RIG_CASES)
def test_pose_reports_bad_rig_and_writes_nothing(tmp_path, case):
    text = case.apply(RIG)
    rig = write(tmp_path, "rig.yaml", text)
    assert_case_error(pose(tmp_path, rig=rig), case, rig, text)
    assert not any((tmp_path / "out" / name).exists() for name in OUTPUTS)


@pytest.mark.parametrize("case", SCRIPT_CASES)
def test_pose_reports_bad_script_and_writes_nothing(tmp_path, case):
    text = case.apply(SCRIPT)
    result = pose(tmp_path, script=text)
    assert_case_error(result, case, tmp_path / "script.yaml", text)
    assert not any((tmp_path / "out" / name).exists() for name in OUTPUTS)


def test_missing_rig_is_a_usage_error(tmp_path):
    result = invoke("validate", tmp_path / "nothing.yaml")
    assert result.exit_code == 2
    assert "nothing.yaml" in result.stderr and "does not exist" in result.stderr


# -- outputs --------------------------------------------------------------------------------


def test_pose_writes_keyframes_and_trace(tmp_path):
    result = pose(tmp_path)
    assert result.exit_code == 0, result.output
    out = tmp_path / "out"
    assert sorted(p.name for p in out.iterdir()) == sorted(OUTPUTS)
    keys = read_keys(out / "keyframes.json")
    assert [k["label"] for k in keys] == script_labels(SCRIPT)
    assert [k["time"] for k in keys] == pytest.approx([0.0, 0.2], abs=1e-9)  # push 0.1 + wait 0.1
    assert set(keys[0]["bones"]) == {b["name"] for b in yaml.safe_load(RIG)["bones"]}
    joints = read_mcap(out / "trace.mcap")["/puppet/joints"]
    assert joints[-1] == round(0.2e9)


def test_pose_draws_every_key(tmp_path):
    rig = write(tmp_path, "rig.yaml", RIG)
    script_path = write(tmp_path, "script.yaml", SCRIPT)
    result = invoke("pose", rig, script_path, "-o", tmp_path / "out")
    assert result.exit_code == 0, result.output
    out = tmp_path / "out"
    n = len(script_labels(SCRIPT))
    assert sorted(p.name for p in (out / "keys").iterdir()) == [
        f"{i:03d}.png" for i in range(1, n + 1)
    ]
    assert (out / "sheet.png").stat().st_size > 0
    again = invoke("pose", rig, script_path, "-o", out)
    assert again.exit_code == 1 and "--force" in again.stderr  # pictures are outputs too


@pytest.mark.parametrize("existing", OUTPUTS)
def test_pose_refuses_to_overwrite_without_force(tmp_path, existing):
    assert pose(tmp_path).exit_code == 0
    out = tmp_path / "out"
    for name in OUTPUTS:
        if name != existing:
            (out / name).unlink()
    before = snapshot(out)
    result = pose(tmp_path)
    assert_one_error(result, "error: ", (str(out / existing), "--force"))
    assert snapshot(out) == before


def test_pose_force_overwrites(tmp_path):
    assert pose(tmp_path).exit_code == 0
    out = tmp_path / "out"
    first = (out / "keyframes.json").read_bytes()
    for name in OUTPUTS:
        (out / name).write_bytes(b"stale")
    result = pose(tmp_path, "--force")
    assert result.exit_code == 0, result.output
    assert (out / "keyframes.json").read_bytes() == first  # the run is deterministic
    assert read_mcap(out / "trace.mcap")["/puppet/joints"]
    assert hidden_files(out) == []


def test_pose_output_path_that_is_a_file(tmp_path):
    write(tmp_path, "out", "not a directory")
    result = pose(tmp_path)
    assert result.exit_code == 2  # click's usage error: -o must be a directory
    assert str(tmp_path / "out") in result.stderr and "is a file" in result.stderr
    assert (tmp_path / "out").read_text() == "not a directory"


# -- a failing simulation ---------------------------------------------------------------------


@dataclass(frozen=True)
class BlowUp:
    result: Result
    out: Path
    h: float
    steps_before: int  # the wait's steps; the push's first step fails


@pytest.fixture(scope="module")
def blow_up(tmp_path_factory) -> BlowUp:
    tmp_path = tmp_path_factory.mktemp("blow_up")
    h = yaml.safe_load(ONE_BONE.read_text(encoding="utf-8"))["solver"]["h"]
    result = pose(tmp_path, rig=ONE_BONE, script=BLOW_UP)
    return BlowUp(result, tmp_path / "out", h, round(0.1 / h))


def test_blow_up_error_names_step_time_and_bone(blow_up):
    line = assert_one_error(blow_up.result, "error: simulation failed at step ")
    pattern = r"error: simulation failed at step (\d+) \(t = (\S+) s\), bone 'bone': .+"
    found = re.fullmatch(pattern, line)
    assert found, line
    assert int(found[1]) == blow_up.steps_before
    assert float(found[2]) == pytest.approx(blow_up.steps_before * blow_up.h, rel=1e-5)


def test_blow_up_keeps_the_keys_taken_before(blow_up):
    keys = read_keys(blow_up.out / "keyframes.json")
    assert [k["label"] for k in keys] == ["rest", "before"]
    times = [k["time"] for k in keys]
    assert times == pytest.approx([0.0, blow_up.steps_before * blow_up.h], abs=1e-9)
    for key in keys:  # no gravity, nothing pushed yet: still at rest
        assert key["bones"]["bone"]["rotation"] == pytest.approx([1, 0, 0, 0], abs=1e-9)
    assert hidden_files(blow_up.out) == []


def test_blow_up_keeps_a_readable_trace_up_to_the_failure(blow_up):
    times = read_mcap(blow_up.out / "trace.mcap")
    fail_ns = round(blow_up.steps_before * blow_up.h * 1e9)
    # The last state written is the last good one, where the failed step began.
    assert times["/puppet/joints"][-1] == fail_ns
    assert max(max(t) for t in times.values() if t) <= fail_ns


# -- validate summary -------------------------------------------------------------------------


def test_validate_doll_summary():
    doc = yaml.safe_load(DOLL.read_text(encoding="utf-8"))
    items = doc["bones"] + doc.get("props", [])
    assert all("mass" in b for b in doc["bones"])
    result = invoke("validate", DOLL)
    assert result.exit_code == 0, result.output
    bones, joints, mass = summary_numbers(result.stdout)
    assert (bones, joints) == (17, 16) == (len(doc["bones"]), len(doc["bones"]) - 1)
    assert mass == pytest.approx(sum(b["mass"] for b in items if "mass" in b), abs=5e-4)


def test_validate_small_rig_mass_from_density(tmp_path):
    r, length = 0.04, 0.2  # neck: capsule of the default radius, density 900
    neck = 900 * (math.pi * r**2 * length + 4 / 3 * math.pi * r**3)
    result = invoke("validate", write(tmp_path, "rig.yaml", RIG))
    assert result.exit_code == 0, result.output
    assert summary_numbers(result.stdout) == (3, 2, pytest.approx(2.0 + 1.5 + neck, abs=5e-4))


def test_validate_states_the_step_and_the_contacts_slop(tmp_path):
    result = invoke("validate", write(tmp_path, "rig.yaml", RIG))
    assert "step h = 0.005 s, integrator euler;" in result.stdout
    assert "collision on (a contact sinks up to 0.5 mm" in result.stdout
    given = RIG + "solver: {h: 0.002, integrator: bdf2, contact_slop: 0}\n"
    result = invoke("validate", write(tmp_path, "rig.yaml", given))
    assert result.exit_code == 0, result.output
    assert "step h = 0.002 s, integrator bdf2;" in result.stdout
    assert "collision on (a contact sinks up to 0 mm" in result.stdout


def test_validate_one_bone_skips_collision():
    result = invoke("validate", ONE_BONE)
    assert result.exit_code == 0, result.output
    assert "collision skipped" in result.stdout
    assert summary_numbers(result.stdout)[:2] == (1, 1)  # root: ball hangs by one joint


# -- help, version, unknown commands ----------------------------------------------------------


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (["--help"], ["validate", "pose"]),
        (["-h"], ["validate", "pose"]),
        (["validate", "--help"], ["RIG"]),
        (["pose", "--help"], ["RIG SCRIPT", "--force"]),
    ],
    ids=lambda v: " ".join(v),
)
def test_help(args, words):
    result = invoke(*args)
    assert result.exit_code == 0, result.output
    assert result.stdout.startswith("Usage: ")
    assert all(w in result.stdout for w in words)


def test_version():
    result = invoke("--version")
    assert result.exit_code == 0
    assert importlib.metadata.version("puppetcli") in result.stdout


def test_unknown_command_is_a_usage_error():
    result = invoke("nosuchcommand")
    assert result.exit_code == 2
    assert "No such command 'nosuchcommand'" in result.stderr
    assert "Traceback" not in result.output


def test_an_output_the_file_system_refuses_is_one_line_and_the_trace_is_kept(tmp_path):
    """pose --force into a folder where keyframes.json is a directory: the run's trace is
    written, then the keys' JSON cannot be, and that is one line naming it, exit 1."""
    (tmp_path / "out" / "keyframes.json").mkdir(parents=True)
    result = invoke("pose", DOLL, ROOT / "scripts" / "wave.yaml", "-o", tmp_path / "out", "--force")
    assert_one_error(result, f"error: {tmp_path / 'out' / 'keyframes.json'}: cannot write: ")
    assert (tmp_path / "out" / "trace.mcap").stat().st_size > 0
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["keyframes.json", "trace.mcap"]
