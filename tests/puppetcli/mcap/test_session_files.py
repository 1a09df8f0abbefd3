"""Session files: read back by the official mcap readers, deterministic, noise, and one clear
error line for every kind of bad session (the broken files are written here)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from mcap.reader import make_reader
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer
from scipy.stats import norm

from puppetcli.cli import cli
from puppetcli.mcap.session import CHANNELS, METADATA_NAME, read_session
from puppetcli.mcap.trace import load_schema
from puppetcli.run.keyframes import read_keyframes
from puppetcli.spidar import counts_from_pose, preset, structure_matrix

ROOT = Path(__file__).resolve().parents[3]
DOLL = ROOT / "rigs/doll.yaml"
WAVE = ROOT / "scripts/wave.yaml"
HEAD = ROOT / "scripts/head_twist.yaml"


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def one_error(result) -> str:
    assert result.exit_code == 1, result.output
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), result.stderr
    return lines[0][len("error: ") :]


def read_all(path: Path) -> dict[str, list[dict]]:
    """Every message through both official readers, CRCs validated; log time non-decreasing."""
    out: dict[str, list[dict]] = {}
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        assert reader.get_summary().chunk_indexes  # chunked and indexed
        last = 0
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            assert schema is not None and schema.encoding == "jsonschema"
            assert channel.message_encoding == "json"
            assert message.log_time >= last
            last = message.log_time
            out.setdefault(channel.topic, []).append(json.loads(message.data))
    with open(path, "rb") as f:
        records = list(StreamReader(f, validate_crcs=True).records)
    assert type(records[-1]).__name__ == "Footer"
    return out


@pytest.fixture(scope="module")
def wave_session(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("wave") / "wave.mcap"
    assert run("record", DOLL, WAVE, "-o", path).exit_code == 0
    return path


def test_session_and_trace_read_back_with_the_official_reader(wave_session, tmp_path):
    messages = read_all(wave_session)
    counts = messages["/spidar/counts"]
    assert len(counts) == 3501 and all(len(m["counts"]) == 8 for m in counts)
    assert [m["t"] for m in counts[:3]] == [0.0, 0.001, 0.002]
    grips = [m for m in messages["/spidar/buttons"] if m["button"] == "grip"]
    assert [(m["state"], m.get("bone")) for m in grips] == [("down", "forearm_l"), ("up", None)]
    assert grips[0]["point"] == pytest.approx([0.24, 0.0, 0.0], abs=3e-16)  # measured 5.5e-17
    labels = [m["label"] for m in messages["/spidar/buttons"] if m.get("label")]
    assert labels == ["rest", "raised", "held"]
    with open(wave_session, "rb") as f:
        meta = {m.name: m.metadata for m in make_reader(f).iter_metadata()}[METADATA_NAME]
    assert meta["device"] == "SpidarG6X3R"
    workspace = json.loads(meta["workspace"])
    # The fitted workspace puts the path within 80 % of the reach (0.0375 m on the G6X3R).
    session = read_session(wave_session)
    radius = np.linalg.norm(
        np.array([[0.70, 1.36, 0.0], [0.55, 1.76, 0.15]]) - workspace["offset"], axis=1
    ).max()
    assert radius / workspace["scale"] <= 0.8 * 0.0375 + 1e-12
    assert session.workspace.fitted

    out = tmp_path / "replay"
    assert run("pose", DOLL, wave_session, "-o", out, "--no-render").exit_code == 0
    trace = read_all(out / "trace.mcap")
    steps = len(trace["/puppet/joints"])
    assert len(trace["/spidar/tensions"]) == len(trace["/spidar/estimate"]) == steps
    dev = preset("SpidarG6X3R")
    for m in trace["/spidar/tensions"][::50]:
        t = np.array(m["tensions"])
        assert np.all(t >= dev.t_min) and np.all(t <= dev.t_max)  # t_min reached exactly
    # The displayed force is Aᵀt at the estimated pose: recompute it independently.
    k = steps // 2
    est, shown = trace["/spidar/estimate"][k], trace["/spidar/tensions"][k]
    a = structure_matrix(dev, np.array(est["device"]["position"]), est["device"]["orientation"])
    wrench = a.T @ np.array(shown["tensions"])
    # measured 0 (the same floats through JSON); 1e-14: rounding of forces of ~10 N
    np.testing.assert_allclose(wrench[:3], shown["displayed"]["force"], rtol=0, atol=1e-14)
    np.testing.assert_allclose(wrench[3:], shown["displayed"]["torque"], rtol=0, atol=1e-14)


def test_record_is_deterministic_and_noise_changes_counts_only_a_little(wave_session, tmp_path):
    again = tmp_path / "again.mcap"
    assert run("record", DOLL, WAVE, "-o", again).exit_code == 0
    assert again.read_bytes() == wave_session.read_bytes()
    noisy, noisy2 = tmp_path / "noisy.mcap", tmp_path / "noisy2.mcap"
    for path in (noisy, noisy2):
        assert run("record", DOLL, WAVE, "-o", path, "--noise", 1.5, "--seed", 7).exit_code == 0
    assert noisy.read_bytes() == noisy2.read_bytes()
    clean, dirty = read_session(wave_session).counts, read_session(noisy).counts
    # σ = 1.5 rounded to whole counts: at most 8σ (measured 6), and the standard deviation
    # of rint(N(0, σ²)), summed over its integers (within 5 standard errors of a standard
    # deviation from 28,008 samples, 0.42 %; measured 0.39 % off)
    assert np.any(clean != dirty) and np.abs(clean - dirty).max() <= 12
    k = np.arange(-20, 21)
    rounded_sd = np.sqrt(np.sum(k**2 * (norm.cdf((k + 0.5) / 1.5) - norm.cdf((k - 0.5) / 1.5))))
    assert np.std(clean - dirty) == pytest.approx(rounded_sd, rel=0.021)
    for name, path in (("clean", wave_session), ("noisy", noisy)):
        assert run("pose", DOLL, path, "-o", tmp_path / name, "--no-render").exit_code == 0
    _, a = read_keyframes(tmp_path / "clean" / "keyframes.json")
    _, b = read_keyframes(tmp_path / "noisy" / "keyframes.json")
    for ka, kb in zip(a, b, strict=True):
        for bone in ka.bones:
            d = 2 * np.arccos(min(1.0, abs(np.dot(ka.bones[bone].local, kb.bones[bone].local))))
            assert np.degrees(d) < 0.4  # measured 0.079°


def test_replay_at_another_physics_step(tmp_path):
    session = tmp_path / "head.mcap"
    assert run("record", DOLL, HEAD, "-o", session, "--with-pose").exit_code == 0
    assert "/spidar/pose" in read_all(session)
    result = run("pose", DOLL, session, "-o", tmp_path / "h20", "--no-render", "--h", 0.02)
    assert result.exit_code == 0, result.output
    assert "125 steps of 0.02 s" in result.stdout and "3 of 3 passed" in result.stdout


def test_record_errors(tmp_path):
    far = tmp_path / "far.yaml"
    far.write_text(
        "pointer: {start: [0.7, 1.36, 0.0]}\nworkspace: {offset: [0.7, 1.36, 0.0], scale: 4}\n"
        "actions:\n  - wait: 0.1\n  - move: {by: [0.0, 0.5, 0.0], duration: 0.5}\n"
    )
    message = one_error(run("record", DOLL, far, "-o", tmp_path / "far.mcap"))
    assert message.startswith(f"{far}:5: at t = ")
    assert "expected a pointer pose the device's strings can reach" in message
    assert "outside the frame" in message
    assert not (tmp_path / "far.mcap").exists()
    message = one_error(run("record", DOLL, WAVE, "-o", tmp_path / "x.mcap", "--device", "G6X9"))
    assert message.startswith("unknown device preset 'G6X9'")
    (tmp_path / "keep.mcap").write_text("keep")
    message = one_error(run("record", DOLL, WAVE, "-o", tmp_path / "keep.mcap"))
    assert message == f"{tmp_path / 'keep.mcap'} exists: pass --force to overwrite"


# --- bad sessions ------------------------------------------------------------------------------

GOOD_META = {
    "format": "1",
    "device": "SpidarG6X3R",
    "calibration": json.dumps({"home_counts": [0] * 8, "tick": 0.001}),
    "workspace": json.dumps({"offset": [0.0, 1.2, 0.6], "scale": 4.0}),
}


def write_raw(
    path: Path, messages, *, schemas=None, meta=GOOD_META, topics=None, in_order=True
) -> Path:
    """A session written by hand: messages (topic, t, dict), sorted by time unless not
    ``in_order``; schemas: topic → schema name or None."""
    if in_order:
        messages = sorted(messages, key=lambda m: m[1])
    schemas = {**CHANNELS, **(schemas or {})}
    topics = topics or ["/spidar/counts", "/spidar/buttons"]
    with open(path, "wb") as f:
        writer = Writer(f, compression=CompressionType.ZSTD, enable_data_crcs=True)
        writer.start(profile="", library="test")
        ids = {}
        for topic in topics:
            schema_id = 0
            if schemas[topic] is not None:
                data = json.dumps(load_schema(CHANNELS[topic])).encode()
                schema_id = writer.register_schema(schemas[topic], "jsonschema", data)
            ids[topic] = writer.register_channel(topic, "json", schema_id)
        if meta is not None:
            writer.add_metadata(METADATA_NAME, meta)
        for seq, (topic, t, body) in enumerate(messages):
            ns = round(t * 1e9)
            writer.add_message(ids[topic], ns, json.dumps({"t": t, **body}).encode(), ns, seq)
        writer.finish()
    return path


def ticks(n: int = 60, counts=None):
    row = [0] * 8 if counts is None else counts
    return [("/spidar/counts", k * 0.001, {"counts": row}) for k in range(n)]


KEY = [("/spidar/buttons", 0.02, {"button": "key", "state": "down", "label": "a"})]


def test_a_good_hand_written_session_replays(tmp_path):
    path = write_raw(tmp_path / "good.mcap", ticks() + KEY)
    result = run("pose", DOLL, path, "-o", tmp_path / "out", "--no-render")
    assert result.exit_code == 0, result.output
    _, keys = read_keyframes(tmp_path / "out" / "keyframes.json")
    assert [k.label for k in keys] == ["a"] and keys[0].time == pytest.approx(0.02)


def bad(tmp_path: Path, path: Path) -> str:
    message = one_error(run("pose", DOLL, path, "-o", tmp_path / "out", "--no-render"))
    assert not (tmp_path / "out" / "keyframes.json").exists()
    assert message.startswith(f"{path}: ")
    return message[len(f"{path}: ") :]


def test_a_session_that_ended_abruptly_replays_what_it_holds(tmp_path):
    """A recording killed before its summary: everything up to its last whole chunk is
    replayed (here all of it: only the summary and footer are cut), with a warning."""
    good = write_raw(tmp_path / "good.mcap", ticks() + KEY)
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(good.read_bytes()[:-100])
    assert not read_session(cut).complete and read_session(good).complete
    result = run("pose", DOLL, cut, "-o", tmp_path / "out", "--no-render")
    assert result.exit_code == 0, result.output
    assert f"warning: {cut}: the recording ended abruptly" in result.stderr
    run("pose", DOLL, good, "-o", tmp_path / "full", "--no-render")
    _, keys = read_keyframes(tmp_path / "out" / "keyframes.json")
    _, full = read_keyframes(tmp_path / "full" / "keyframes.json")
    assert [k.time for k in keys] == [k.time for k in full] and len(keys) == 1
    assert keys[0].bones == full[0].bones


def test_a_file_cut_before_its_first_chunk(tmp_path):
    good = write_raw(tmp_path / "good.mcap", ticks() + KEY)
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(good.read_bytes()[:300])  # header and metadata, no whole chunk
    assert bad(tmp_path, cut).startswith("expected a complete MCAP file, got a truncated")


def test_missing_and_wrong_schema(tmp_path):
    missing = write_raw(tmp_path / "m.mcap", ticks(), schemas={"/spidar/counts": None})
    assert bad(tmp_path, missing) == (
        "channel /spidar/counts: expected schema 'puppetcli.SpidarCounts' (jsonschema), "
        "got no schema"
    )
    wrong = write_raw(tmp_path / "w.mcap", ticks(), schemas={"/spidar/counts": "foxglove.Log"})
    assert bad(tmp_path, wrong) == (
        "channel /spidar/counts: expected schema 'puppetcli.SpidarCounts' (jsonschema), "
        "got 'foxglove.Log' (jsonschema)"
    )


def test_missing_channel_and_metadata(tmp_path):
    path = write_raw(tmp_path / "c.mcap", ticks(), topics=["/spidar/counts"])
    assert bad(tmp_path, path) == (
        "channels: expected /spidar/counts (or /spidar/pose) and /spidar/buttons, "
        "got /spidar/counts"
    )
    path = write_raw(tmp_path / "n.mcap", ticks(), meta=None)
    assert bad(tmp_path, path).startswith("metadata: expected a 'puppetcli.mcap.session' record")


def test_counts_of_the_wrong_length(tmp_path):
    messages = ticks(5) + [("/spidar/counts", 0.005, {"counts": [0] * 7})]
    path = write_raw(tmp_path / "l.mcap", messages)
    assert bad(tmp_path, path) == (
        "/spidar/counts[5]: counts: expected 8 integers (one per string), got 7 values"
    )


def test_time_going_backwards(tmp_path):
    messages = ticks(5) + [("/spidar/counts", 0.002, {"counts": [0] * 8})]
    path = write_raw(tmp_path / "b.mcap", messages, in_order=False)
    assert bad(tmp_path, path) == (
        "/spidar/counts[5]: log time: expected time never to go backwards (>= 4000000 ns), "
        "got 2000000 ns"
    )


def test_unknown_preset(tmp_path):
    meta = {**GOOD_META, "device": "SpidarG6X3Q"}
    path = write_raw(tmp_path / "p.mcap", ticks(), meta=meta)
    assert bad(tmp_path, path).startswith(
        "metadata.device: unknown device preset 'SpidarG6X3Q' (did you mean 'SpidarG6X3R'?)"
    )


def test_unreachable_grip_pose(tmp_path):
    dev = preset("SpidarG6X3R")
    outside = counts_from_pose(dev, np.array([0.09, 0.0, 0.0]), np.array([1.0, 0, 0, 0]), False)
    messages = ticks(5) + [("/spidar/counts", 0.005, {"counts": outside.tolist()})]
    path = write_raw(tmp_path / "u.mcap", messages)
    message = bad(tmp_path, path)
    assert message.startswith("/spidar/counts[5] (t = 0.005 s): expected a grip pose the strings")
    assert "outside the frame" in message
    stored = [("/spidar/pose", 0.0, {"position": [0.2, 0, 0], "orientation": [1, 0, 0, 0]})]
    path = write_raw(tmp_path / "s.mcap", stored, topics=["/spidar/pose", "/spidar/buttons"])
    assert bad(tmp_path, path).startswith("/spidar/pose[0] (t = 0.000 s): expected a grip pose")


def test_grip_without_bone_needs_a_bone_within_reach(tmp_path):
    grip = [("/spidar/buttons", 0.01, {"button": "grip", "state": "down"})]
    path = write_raw(tmp_path / "g.mcap", ticks() + grip)
    message = one_error(run("pose", DOLL, path, "-o", tmp_path / "out", "--no-render"))
    assert message.startswith(f"{path}: /spidar/buttons grip at t = 0.010 s: expected a bone")


def test_undo_drops_the_last_key_and_labels_count_every_key(tmp_path):
    def press(t, button, **extra):
        return ("/spidar/buttons", t, {"button": button, "state": "down", **extra})

    events = [press(0.01, "key"), press(0.02, "key", label="b"), press(0.03, "undo"),
              press(0.04, "key"), press(0.05, "undo"), press(0.05, "undo")]  # fmt: skip
    path = write_raw(tmp_path / "undo.mcap", ticks() + events)
    result = run("pose", DOLL, path, "-o", tmp_path / "out", "--no-render")
    assert result.exit_code == 0, result.output
    _, keys = read_keyframes(tmp_path / "out" / "keyframes.json")
    # key 1, b (undone), key 3 (undone), then an undo with one key left: key 1 goes too
    assert [k.label for k in keys] == []
    path = write_raw(tmp_path / "undo2.mcap", ticks() + events[:4])
    run("pose", DOLL, path, "-o", tmp_path / "out2", "--no-render")
    _, keys = read_keyframes(tmp_path / "out2" / "keyframes.json")
    assert [(k.label, round(k.time, 3)) for k in keys] == [("key 1", 0.01), ("key 3", 0.04)]


def test_a_session_of_a_newer_format_is_refused(tmp_path):
    path = write_raw(tmp_path / "new.mcap", ticks() + KEY, meta={**GOOD_META, "format": "4"})
    assert bad(tmp_path, path) == (
        "metadata.format: expected 1 or 2 or 3 (a newer puppetcli wrote this file), got '4'"
    )
