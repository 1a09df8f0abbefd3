"""One named regression per class of bad input (issue 19), each on the smallest input that
showed it: what is read is bounded by what is there, numbers are checked where they are read,
nothing numpy says reaches the user, errors are one printable line, a failed run leaves
existing outputs as they were, and every command keeps the README's exit-status table."""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml
from fuzz_harness import Outcome, run_cli
from fuzz_kinds import mcap_messages, write_mcap
from fuzz_mutate import deep, expand_deep
from mcap.reader import make_reader

from puppetcli.errors import MAX_LINE, clip, one_line, shown

ROOT = Path(__file__).resolve().parents[3]
DOLL = ROOT / "rigs" / "doll.yaml"
WAVE = ROOT / "scripts" / "wave.yaml"
SHORT = """\
pointer: {start: [0.70, 1.36, 0.0]}
actions:
  - key: rest
  - grip: {bone: forearm_l, point: [0.24, 0.0, 0.0], position_only: true}
  - move: {by: [0.0, 0.05, 0.0], duration: 0.5}
  - key: up
  - release:
  - wait: 1.5
  - key: end
"""


def one_error(outcome: Outcome, code: int) -> str:
    """The only ``error:`` line of a failed run with exit status ``code``, and no problem."""
    assert outcome.code == code, (outcome.code, outcome.stderr, outcome.exception)
    assert outcome.problems() == []
    lines = [line for line in outcome.stderr.splitlines() if line.startswith("error:")]
    assert len(lines) == 1, outcome.stderr
    return lines[0]


@pytest.fixture
def short(tmp_path: Path) -> Path:
    path = tmp_path / "short.yaml"
    path.write_text(SHORT)
    return path


# ---- sizes from the input ------------------------------------------------------------------


def deep_bvh(levels: int) -> str:
    joints = "".join(f"JOINT j{i}\n{{\nOFFSET 0 0.01 0\nCHANNELS 3 Zrotation Xrotation Yrotation\n"
                     for i in range(levels))  # fmt: skip
    return (
        "HIERARCHY\nROOT r\n{\nOFFSET 0 0 0\nCHANNELS 3 Zrotation Xrotation Yrotation\n"
        + joints + "End Site\n{\nOFFSET 0 0.01 0\n}\n" + "}\n" * (levels + 1)
        + "MOTION\nFrames: 1\nFrame Time: 0.03\n" + "0 " * (3 + 3 * levels) + "\n"
    )  # fmt: skip


def test_a_bvh_nested_deeper_than_any_skeleton_is_one_line(tmp_path: Path) -> None:
    """20,000 nested joints once recursed until RecursionError; a chain of 512 (the most
    bones a rig may have) is read, made a rig, written back as BVH and read again."""
    path = tmp_path / "deep.bvh"
    path.write_text(deep_bvh(20_000))
    line = one_error(run_cli(["rig", "from-bvh", str(path), "-o", str(tmp_path / "r.yaml")]), 1)
    assert "expected joints nested at most 512 deep" in line
    path.write_text(deep_bvh(511))
    assert run_cli(["rig", "from-bvh", str(path), "-o", str(tmp_path / "r.yaml")]).code == 0
    script = tmp_path / "s.yaml"
    script.write_text("actions:\n  - key: a\n  - wait: 0.01\n  - key: b\n")
    out = tmp_path / "out"
    posed = run_cli(["pose", str(tmp_path / "r.yaml"), str(script), "-o", str(out),
                     "--no-render", "--no-trace"])  # fmt: skip
    assert posed.code == 0, posed.stderr
    again = run_cli(["rig", "from-bvh", str(out / "keyframes.bvh"), "-o", str(tmp_path / "2.yaml")])
    assert again.code == 0 and "512 bones" in again.stdout, again.stderr


def test_a_rig_of_thousands_of_bones_is_refused_before_it_fills_the_memory(tmp_path: Path):
    """1,000 bones took 5 GB in the step's dense solves and 3,000 were killed for memory."""
    bones = [f"  - {{name: b{i}{f', parent: b{i - 1}' if i else ''}, head: [0, {i}, 0], "
             f"tail: [0, {i + 1}, 0]}}" for i in range(1000)]  # fmt: skip
    rig = tmp_path / "long.yaml"
    rig.write_text("name: long\nroot: fixed\nbones:\n" + "\n".join(bones) + "\n")
    line = one_error(run_cli(["validate", str(rig)]), 1)
    assert line.startswith(f"error: {rig}:4: bones: expected at most 512 bones (")  # the list
    assert line.endswith("got 1,000 bones")


def test_a_bvh_declaring_billions_of_frames_is_refused_before_allocating(tmp_path: Path):
    """``Frames: 4294967297`` over one frame line once asked numpy for 1.7 TiB."""
    path = tmp_path / "many.bvh"
    path.write_text(deep_bvh(2).replace("Frames: 1", "Frames: 4294967297"))
    line = one_error(run_cli(["render", str(path), "--rig", str(DOLL), "-o", "s.png"]), 1)
    assert "expected as many frame lines as 'Frames:' says ('4294967297'), got at most 2" in line


@pytest.mark.parametrize("suffix", [".json", ".mcap"])
def test_json_nested_too_deeply_is_one_line(tmp_path: Path, suffix: str) -> None:
    """keyframes.json, and a session's message, of 100,000 nested lists (RecursionError)."""
    if suffix == ".json":
        path = tmp_path / "keyframes.json"
        path.write_text(expand_deep(f'{{"rig": "doll", "keys": {deep(100_000)}}}'))
        args = ["render", str(path), "--rig", str(DOLL), "-o", str(tmp_path / "s.png")]
        expected = ": expected JSON, got nesting too deep to read"
    else:
        session = tmp_path / "s.mcap"
        assert run_cli(["record", str(DOLL), str(WAVE), "-o", str(session)]).code == 0
        metadata, messages = mcap_messages(session)
        topic, schema, log_time, _ = messages[5]
        messages[5] = (topic, schema, log_time, deep(100_000))
        path = tmp_path / "deep.mcap"
        write_mcap(path, metadata, messages)
        args = ["pose", str(DOLL), str(path), "-o", str(tmp_path / "out")]
        expected = ": expected a JSON message, got b'[[[["
    line = one_error(run_cli(args), 1)
    assert f"error: {path}:" in line and expected in line


# ---- non-finite or absurd numbers, options and durations ---------------------------------


@pytest.mark.parametrize(
    ("option", "value", "words"),
    [
        ("--scale", "inf", "inf is not in the range 1e-06<=x<=1000000.0"),
        ("--scale", "nan", "'nan' is not a finite number in the range 1e-06<=x<=1000000.0"),
        ("--fps", "1e6", "1000000.0 is not in the range 0.001<=x<=1000.0"),
        ("--h", "1e-7", "1e-07 is not in the range 1e-05<=x<=0.1"),
        ("--view", "custom:0,0,inf", "expected one of front, side, top, iso or custom:"),
    ],
)
def test_an_absurd_option_is_a_usage_error_before_anything_runs(
    tmp_path: Path, short: Path, option: str, value: str, words: str
) -> None:
    out = tmp_path / "out"
    line = one_error(run_cli(["pose", str(DOLL), str(short), "-o", str(out), option, value]), 2)
    assert line == (f"error: Invalid value for '{option}': {words}"
                    + line[line.index(words) + len(words):])  # fmt: skip
    assert line.endswith("(see 'cli pose --help')")
    assert not out.exists()  # refused before the output folder or any simulation


@pytest.mark.parametrize(
    ("old", "new", "words"),
    [
        ("duration: 0.5", "duration: 1e300", "of magnitude at most 1e+09, got 1e300"),
        ("duration: 0.5", "duration: .nan", "expected a positive finite number, got .nan"),
        ("[0.24, 0.0, 0.0]", "[0.24, 1e12, 0.0]", "of magnitude at most 1e+09, got 1e12"),
        ("duration: 0.5", "duration: 1e-300", "of at least 1e-09, got 1e-300"),
    ],
)
def test_a_number_out_of_every_range_is_refused_where_it_is_read(
    tmp_path: Path, short: Path, old: str, new: str, words: str
) -> None:
    short.write_text(SHORT.replace(old, new))
    line = one_error(run_cli(["pose", str(DOLL), str(short), "-o", str(tmp_path / "o")]), 1)
    assert line.startswith(f"error: {short}:") and line.endswith(words)


def test_a_run_of_hours_is_refused_up_front_and_yes_runs_it(
    tmp_path: Path, short: Path, monkeypatch
) -> None:
    """h = 1e-5 s for 100,000 s: ~10^10 steps, refused with the estimate; nothing written.
    --yes lifts the refusal (shown on a short run under a zero limit, which it alone passes)."""
    short.write_text("h: 1.0e-5\nduration: 100000\n" + SHORT)
    out = tmp_path / "out"
    line = one_error(run_cli(["pose", str(DOLL), str(short), "-o", str(out)]), 1)
    assert line.startswith(f"error: {short}: expected a run of at most 10 min, got about ")
    assert "(10,000,000,000 steps of h = 1e-05 s, 17 bones)" in line and "--yes" in line
    assert not out.exists()
    short.write_text(SHORT)
    monkeypatch.setenv("PUPPETCLI_RUN_LIMIT", "0")
    refused = run_cli(["pose", str(DOLL), str(short), "-o", str(out), "--no-render"])
    accepted = run_cli(["pose", str(DOLL), str(short), "-o", str(out), "--no-render", "--yes"])
    assert "expected a run of at most 0 s" in one_error(refused, 1)
    assert accepted.code == 0, accepted.stderr


def test_nan_in_a_session_is_one_line(tmp_path: Path) -> None:
    session = tmp_path / "s.mcap"
    assert run_cli(["record", str(DOLL), str(WAVE), "-o", str(session)]).code == 0
    metadata, messages = mcap_messages(session)
    i = next(i for i, m in enumerate(messages) if m[0] == "/spidar/counts")
    messages[i][3]["counts"][2] = math.nan
    write_mcap(tmp_path / "nan.mcap", metadata, messages)
    line = one_error(run_cli(["pose", str(DOLL), str(tmp_path / "nan.mcap"), "-o", "o"]), 1)
    assert "/spidar/counts[" in line and "counts: expected 8 integers" in line
    messages[i][3]["counts"][2] = 0
    name, values = metadata[0]
    values = {**values, "settings": json.dumps({"pointer": {"radius": -1}})}
    write_mcap(tmp_path / "radius.mcap", [(name, values)], messages)
    line = one_error(run_cli(["pose", str(DOLL), str(tmp_path / "radius.mcap"), "-o", "o"]), 1)
    assert "metadata.settings" in line and "pointer.radius: expected a positive finite" in line


# ---- warnings leaking ------------------------------------------------------------------------


@pytest.mark.parametrize("engine", ["numpy", "compiled"])
def test_extreme_but_accepted_rigs_run_silently(
    tmp_path: Path, short: Path, engine: str, monkeypatch
) -> None:
    """K_f and masses at the ends of the accepted range: the run ends (posed, stopped by the
    monitor, or stopped by the budget's watch when its 64 substeps a step make it crawl,
    each with one line), and numpy says nothing on the way."""
    monkeypatch.setenv("PUPPETCLI_RUN_LIMIT", "2")
    doc = yaml.safe_load(DOLL.read_text())
    doc["defaults"]["joint"].update(kf=1e9, df=1e9)
    for bone in doc["bones"]:
        bone["mass"] = 1e-9
    rig = tmp_path / "extreme.yaml"
    rig.write_text(yaml.safe_dump(doc))
    outcome = run_cli(["pose", str(rig), str(short), "-o", str(tmp_path / "o"),
                       "--engine", engine, "--no-render"])  # fmt: skip
    assert outcome.code in (0, 1) and outcome.problems() == [], outcome.problems()


# ---- messy error lines -----------------------------------------------------------------------


def test_values_in_errors_are_shortened_and_escaped() -> None:
    text = shown("a\nb\x00" + "x" * 500)
    assert text.startswith("'a\\nb\\x00x") and "..." in text and len(text) <= 45, text
    assert shown(10**400) == "1000000000...00000000000"
    assert shown([[[[1]]]]) == "[[[...]]]"
    assert clip("line one\nline two" * 20) == "line one\\nline twoline one\\nline twolin…"
    long = one_line("x" * 1000)
    assert len(long) <= MAX_LINE and long == "x" * 199 + "…" + "x" * 199
    assert one_line("tab\there\x1b[31m") == "tab\\there\\x1b[31m"


def test_binary_and_multiline_values_in_a_rig_are_one_printable_line(tmp_path: Path) -> None:
    rig = tmp_path / "rig.yaml"
    doc = yaml.safe_load(DOLL.read_text())
    doc["defaults"]["joint"]["kf"] = "\x00\x01binary\nline"
    rig.write_text(yaml.safe_dump(doc))
    line = one_error(run_cli(["validate", str(rig)]), 1)
    assert line.isprintable() and "'\\x00\\x01binary\\nline'" in line


# ---- nothing lost ----------------------------------------------------------------------------


def test_a_failed_render_leaves_the_outputs_of_an_earlier_run(tmp_path: Path, monkeypatch, short):
    out = tmp_path / "out"
    assert run_cli(["pose", str(DOLL), str(short), "-o", str(out)]).code == 0
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    assert len(before) == 7  # keyframes.json, .bvh, trace.mcap, sheet.png, keys/001…003.png

    def broken(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr("puppetcli.render.picture.contact_sheet", broken)
    outcome = run_cli(["pose", str(DOLL), str(short), "-o", str(out), "--force", "--no-trace"])
    assert outcome.code != 0
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == before


# ---- exit status and signals -----------------------------------------------------------------


@pytest.mark.parametrize("command", ["validate", "pose", "convert", "render", "record", "rig"])
def test_a_missing_input_file_is_status_2_for_every_command(tmp_path: Path, command: str):
    missing = str(tmp_path / "missing.yaml")
    args = {
        "validate": ["validate", missing],
        "pose": ["pose", str(DOLL), missing],
        "convert": ["convert", missing, "--rig", str(DOLL), "-o", "o.bvh"],
        "render": ["render", missing, "--rig", str(DOLL), "-o", "s.png"],
        "record": ["record", str(DOLL), missing, "-o", "s.mcap"],
        "rig": ["rig", "from-bvh", missing, "-o", "r.yaml"],
    }[command]
    line = one_error(run_cli(args), 2)
    assert f"File '{missing}' does not exist." in line


def test_ctrl_c_saves_what_the_run_captured_and_exits_130(tmp_path: Path, short: Path):
    """SIGINT a few seconds into a 300 s run: status 130, one line naming the step, and the
    keys taken before it (``rest`` at t = 0) and the trace so far are written.  (A 60 s run
    takes 5.1 s in all on a warm compiled solver, 12,000 steps in 3.8 s: it ended before the
    signal in two runs of 2026-12-04.)"""
    short.write_text("duration: 300\n" + SHORT)
    out = tmp_path / "out"
    env = {**os.environ, "PUPPETCLI_DAEMON": "off"}
    cmd = [sys.executable, "-m", "puppetcli", "pose", str(DOLL), str(short), "-o", str(out),
           "--no-render"]  # fmt: skip
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    time.sleep(5.0)  # start-up (~2 s) and a few seconds of the run
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert err.startswith("error: interrupted at step ") and len(err.splitlines()) == 1, err
    keys = json.loads((out / "keyframes.json").read_text())["keys"]
    assert [k["label"] for k in keys][:1] == ["rest"]
    with (out / "trace.mcap").open("rb") as stream:  # a complete, readable MCAP file
        assert sum(1 for _ in make_reader(stream).iter_messages()) > 100


def test_a_closed_pipe_ends_quietly() -> None:
    env = {**os.environ, "PUPPETCLI_DAEMON": "off"}
    proc = subprocess.Popen([sys.executable, "-m", "puppetcli", "validate", str(DOLL)], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)  # fmt: skip
    proc.stdout.close()  # the reader is gone before the command writes
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=60) == 1 and err == ""
