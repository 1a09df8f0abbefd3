"""trace.mcap: structure checked with the official mcap readers, content against the schemas.

Independent references: mcap's SeekingReader and StreamReader (CRCs validated),
scipy's Rotation (scalar-last quaternions, as Foxglove) for the transform tree,
and a small JSON Schema checker written here (jsonschema is not a dependency).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.records import Channel, Chunk, DataEnd, Footer, Header, Message, Schema, Statistics
from mcap.stream_reader import StreamReader
from scipy.spatial.transform import Rotation

from puppetcli.mcap.trace import (
    STEP_CHANNELS,
    TraceError,
    TraceWriter,
    load_schema,
    read_trace,
)

BONES = ["hips", "spine", "head"]
PARENTS = [-1, 0, 1]
JOINTS = ["spine", "head"]
LENGTHS = np.array([0.1, 0.3, 0.2])
DT = 0.01
TIMES = [0.0, 0.01, 0.02, 1.25]  # the last one past a whole second (sec and nsec both used)
NSTEPS = len(TIMES)
# Foxglove is Z-up: the puppet's Y-up world turned +90° about X (y → z, z → -y).
Y_UP_TO_Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


def chain_pose(rng: np.random.Generator) -> dict[str, np.ndarray]:
    """A 3-bone chain: random world rotations, each head on its parent's tail (bones along +Y)."""
    rot = Rotation.random(3, random_state=rng)
    quat = rot.as_quat(scalar_first=True)
    head = np.empty((3, 3))
    tail = np.empty((3, 3))
    start = rng.standard_normal(3)
    for i in range(3):
        head[i] = start if i == 0 else tail[i - 1]
        tail[i] = head[i] + rot[i].apply([0.0, LENGTHS[i], 0.0])
    return {"bone_head": head, "bone_tail": tail, "bone_quat": quat}


def step_inputs(rng: np.random.Generator, k: int) -> dict[str, Any]:
    """Everything write_step takes for step k."""
    stats = {
        "rows": 9 + k,
        "contacts": k % 2,
        "iterations": 20,
        "residual": 1e-9 * k,
        "solver": "pgs",
    }
    return {
        "joint_rotation": rng.standard_normal((2, 3)),
        "joint_elastic": rng.standard_normal((2, 3)),
        "joint_torque": rng.standard_normal((2, 3)),
        **chain_pose(rng),
        "stats": stats,
    }


@pytest.fixture
def written(tmp_path: Path) -> tuple[Path, list[dict[str, Any]]]:
    """A trace of NSTEPS steps and the inputs that produced it."""
    rng = np.random.default_rng(42)
    inputs = [step_inputs(rng, k) for k in range(NSTEPS)]
    path = tmp_path / "trace.mcap"
    with TraceWriter(path, BONES, PARENTS, JOINTS) as writer:
        for k, step in enumerate(inputs):
            writer.write_step(TIMES[k], **step)
    return path, inputs


# ---- a small JSON Schema checker (the keywords the shipped schemas use) ----

_TYPES = {
    "object": lambda v: isinstance(v, dict),
    "array": lambda v: isinstance(v, list),
    "string": lambda v: isinstance(v, str),
    "boolean": lambda v: isinstance(v, bool),
    "integer": lambda v: isinstance(v, int) and not isinstance(v, bool),
    "number": lambda v: isinstance(v, int | float) and not isinstance(v, bool),
}
_ANNOTATIONS = {"title", "description", "$comment", "contentEncoding"}
_CHECKED = {
    "type",
    "properties",
    "required",
    "items",
    "additionalProperties",
    "oneOf",
    "const",
    "minimum",
    "maximum",
    "minItems",
    "maxItems",
}


def schema_errors(value: Any, schema: dict, where: str = "$") -> list[str]:
    """Violations of ``schema`` by ``value`` (empty when valid)."""
    if "type" in schema and not _TYPES[schema["type"]](value):
        return [f"{where}: expected {schema['type']}, got {value!r}"]
    errors: list[str] = []
    if "const" in schema and (value != schema["const"] or isinstance(value, bool)):
        errors.append(f"{where}: expected {schema['const']!r}, got {value!r}")
    if "oneOf" in schema:
        matches = sum(not schema_errors(value, option, where) for option in schema["oneOf"])
        if matches != 1:
            errors.append(f"{where}: {value!r} matches {matches} oneOf options")
    if "minimum" in schema and value < schema["minimum"]:
        errors.append(f"{where}: {value!r} < minimum {schema['minimum']}")
    if "maximum" in schema and value > schema["maximum"]:
        errors.append(f"{where}: {value!r} > maximum {schema['maximum']}")
    if isinstance(value, list):
        if not schema.get("minItems", 0) <= len(value) <= schema.get("maxItems", len(value)):
            errors.append(f"{where}: {len(value)} items")
        for i, item in enumerate(value):
            errors += schema_errors(item, schema.get("items", {}), f"{where}[{i}]")
    if isinstance(value, dict):
        errors += [f"{where}: missing {k}" for k in schema.get("required", []) if k not in value]
        extra = schema.get("additionalProperties", {})
        for key, item in value.items():
            sub = schema.get("properties", {}).get(key, extra)
            if sub is False:
                errors.append(f"{where}: unexpected {key}")
            else:
                errors += schema_errors(item, sub, f"{where}.{key}")
    return errors


def keywords(schema: Any) -> set[str]:
    """Every JSON Schema keyword used anywhere in ``schema``."""
    if isinstance(schema, list):
        return set().union(*(keywords(s) for s in schema))
    if not isinstance(schema, dict):
        return set()
    found = set(schema) - {"properties"}
    for key, sub in schema.items():
        subs = sub.values() if key == "properties" else [sub]
        found |= set().union(*(keywords(s) for s in subs))
    return found


def test_schema_checker_knows_every_keyword_and_can_fail() -> None:
    """The checker must not silently ignore a keyword, and must catch real faults."""
    for name in [*STEP_CHANNELS.values(), "foxglove.PoseInFrame", "foxglove.Log"]:
        assert keywords(load_schema(name)) <= _CHECKED | _ANNOTATIONS, name
    scene = load_schema("foxglove.SceneUpdate")
    entity = {"timestamp": {"sec": 0, "nsec": 10**9}, "frame_id": "puppet", "id": "x"}
    errors = schema_errors({"deletions": [], "entities": [entity]}, scene)
    assert any("nsec" in e for e in errors) and any("missing lifetime" in e for e in errors)
    line = {"type": 7}
    assert any(
        "oneOf" in e
        for e in schema_errors(
            line, scene["properties"]["entities"]["items"]["properties"]["lines"]["items"]
        )
    )
    joints = load_schema("puppetcli.Joints")
    bad = {"t": 0.0, "joints": {"a": {"rotation": [0, 0], "elastic": [0, 0, 0], "torque": "x"}}}
    assert len(schema_errors(bad, joints)) == 2


def test_schema_files_are_named_by_title() -> None:
    """Foxglove recognises a well-known schema only by its exact name."""
    directory = Path(__file__).parents[3] / "puppetcli" / "schemas"
    files = sorted(directory.glob("*.json"))
    assert len(files) >= 4
    for file in files:
        assert json.loads(file.read_text())["title"] == file.stem


def test_official_reader_sees_indexed_zstd_json_channels(written: tuple[Path, list]) -> None:
    path, _ = written
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        header = reader.get_header()
        summary = reader.get_summary()
        assert header.profile == "" and header.library.startswith("puppetcli ")
        assert {s.name: s.encoding for s in summary.schemas.values()} == {
            name: "jsonschema" for name in STEP_CHANNELS.values()
        }
        channels = {c.topic: c for c in summary.channels.values()}
        assert set(channels) == set(STEP_CHANNELS)
        for topic, channel in channels.items():
            assert channel.message_encoding == "json"
            assert summary.schemas[channel.schema_id].name == STEP_CHANNELS[topic]
            assert json.loads(summary.schemas[channel.schema_id].data) == load_schema(
                STEP_CHANNELS[topic]
            )
        assert summary.chunk_indexes and summary.statistics.message_count == 4 * NSTEPS
        times = [m.log_time for _, _, m in reader.iter_messages(log_time_order=False)]
    assert times == sorted(times)
    assert sorted(set(times)) == [0, 10_000_000, 20_000_000, 1_250_000_000]


def test_stream_reader_walks_every_record_with_crcs(written: tuple[Path, list]) -> None:
    path, _ = written
    with open(path, "rb") as f:
        records = list(StreamReader(f, validate_crcs=True).records)
    kinds = [type(r) for r in records]
    assert kinds[0] is Header and kinds[-1] is Footer
    messages = [r for r in records if isinstance(r, Message)]
    assert len(messages) == 4 * NSTEPS
    assert all(m.publish_time == m.log_time for m in messages)
    assert [m.log_time for m in messages] == sorted(m.log_time for m in messages)
    for m in messages:
        json.loads(m.data)
    data_end = next(r for r in records if isinstance(r, DataEnd))
    assert data_end.data_section_crc != 0  # enable_data_crcs
    assert all(r.encoding == "jsonschema" for r in records if isinstance(r, Schema))
    assert all(r.message_encoding == "json" for r in records if isinstance(r, Channel))
    assert next(r for r in records if isinstance(r, Statistics)).channel_count == 4
    with open(path, "rb") as f:
        chunks = [r for r in StreamReader(f, emit_chunks=True).records if isinstance(r, Chunk)]
    assert chunks and all(c.compression == "zstd" for c in chunks)


def test_messages_validate_against_their_schemas(written: tuple[Path, list]) -> None:
    path, _ = written
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        for schema, channel, message in reader.iter_messages():
            decoded = json.loads(message.data)
            errors = schema_errors(decoded, json.loads(schema.data))
            assert errors == [], (channel.topic, errors[:3])
            for stamped in stamps(decoded):
                assert stamped["sec"] * 10**9 + stamped["nsec"] == message.log_time


def stamps(message: dict) -> list[dict]:
    """The Foxglove timestamps inside a message."""
    items = message.get("transforms", []) + message.get("entities", [])
    return [item["timestamp"] for item in items]


def homogeneous(transform: dict) -> np.ndarray:
    """4×4 matrix of a FrameTransform, via scipy's scalar-last quaternion (Foxglove's order)."""
    r, t = transform["rotation"], transform["translation"]
    matrix = np.eye(4)
    matrix[:3, :3] = Rotation.from_quat([r["x"], r["y"], r["z"], r["w"]]).as_matrix()
    matrix[:3, 3] = [t["x"], t["y"], t["z"]]
    return matrix


def world_poses(message: dict) -> dict[str, np.ndarray]:
    """Compose the transforms down the tree from ``world``: frame → 4×4 pose in world."""
    parent_of = {tf["child_frame_id"]: tf for tf in message["transforms"]}
    assert len(parent_of) == len(message["transforms"])  # a tree: one parent per frame
    poses = {"world": np.eye(4)}

    def pose(frame: str) -> np.ndarray:
        if frame not in poses:
            tf = parent_of[frame]
            poses[frame] = pose(tf["parent_frame_id"]) @ homogeneous(tf)
        return poses[frame]

    for frame in parent_of:
        pose(frame)
    return poses


def test_frame_transforms_compose_to_the_world_pose(written: tuple[Path, list]) -> None:
    path, inputs = written
    tf_messages = read_trace(path)["/tf"]
    assert len(tf_messages) == NSTEPS
    for (_, message), step in zip(tf_messages, inputs, strict=True):
        frames = [(tf["parent_frame_id"], tf["child_frame_id"]) for tf in message["transforms"]]
        assert frames == [
            ("world", "puppet"),
            ("puppet", "hips"),
            ("hips", "spine"),
            ("spine", "head"),
        ]
        poses = world_poses(message)
        assert np.allclose(poses["puppet"][:3, :3], Y_UP_TO_Z_UP, rtol=0, atol=1e-15)
        for i, bone in enumerate(BONES):
            expected_r = Rotation.from_quat(step["bone_quat"][i], scalar_first=True).as_matrix()
            # measured ≤ 4.4e-16 m, 7.8e-16 and 4.4e-16 m
            np.testing.assert_allclose(
                poses[bone][:3, 3], Y_UP_TO_Z_UP @ step["bone_head"][i], rtol=0, atol=4e-15
            )
            np.testing.assert_allclose(
                poses[bone][:3, :3], Y_UP_TO_Z_UP @ expected_r, rtol=0, atol=4e-15
            )
            # The tail lies along the bone's +Y, length LENGTHS[i], in its own frame.
            tail = poses[bone] @ [0.0, LENGTHS[i], 0.0, 1.0]
            np.testing.assert_allclose(
                tail[:3], Y_UP_TO_Z_UP @ step["bone_tail"][i], rtol=0, atol=4e-15
            )


def test_rest_pose_transforms_by_hand(tmp_path: Path) -> None:
    """Identity rotations: translations are plain head offsets; hips at y=1 shows at z=1."""
    path = tmp_path / "rest.mcap"
    head = np.array([[0.0, 1.0, 0.0], [0.0, 1.1, 0.0], [0.0, 1.4, 0.0]])
    with TraceWriter(path, BONES, PARENTS, JOINTS) as writer:
        step = step_inputs(np.random.default_rng(0), 0)
        step.update(
            bone_head=head,
            bone_tail=head + np.array([0, 0.1, 0]),
            bone_quat=np.tile([1.0, 0, 0, 0], (3, 1)),
        )
        writer.write_step(0.0, **step)
    message = read_trace(path)["/tf"][0][1]
    offsets = [[tf["translation"][a] for a in "xyz"] for tf in message["transforms"]]
    np.testing.assert_allclose(  # measured 1.7e-16 (1.4 − 1.1)
        offsets, [[0, 0, 0], [0, 1.0, 0], [0, 0.1, 0], [0, 0.3, 0]], rtol=0, atol=1e-15
    )
    assert message["transforms"][0]["rotation"] == pytest.approx(
        {"x": 0.5**0.5, "y": 0, "z": 0, "w": 0.5**0.5}, abs=1e-16
    )
    assert world_poses(message)["hips"][:3, 3] == pytest.approx([0.0, 0.0, 1.0], abs=1e-15)


def test_bone_scene_and_joint_values(written: tuple[Path, list]) -> None:
    path, inputs = written
    trace = read_trace(path)
    for k, step in enumerate(inputs):
        (entity,) = trace["/puppet/bones"][k][1]["entities"]
        assert entity["frame_id"] == "puppet" and trace["/puppet/bones"][k][1]["deletions"] == []
        (line,) = entity["lines"]
        points = np.array([[p["x"], p["y"], p["z"]] for p in line["points"]])
        assert line["type"] == 2 and len(points) == 2 * len(BONES)
        assert np.array_equal(points[0::2], step["bone_head"])
        assert np.array_equal(points[1::2], step["bone_tail"])
        centres = [[s["pose"]["position"][a] for a in "xyz"] for s in entity["spheres"]]
        assert np.array_equal(centres, step["bone_head"])
        joints = trace["/puppet/joints"][k][1]
        assert joints["t"] == TIMES[k] and list(joints["joints"]) == JOINTS
        for j, name in enumerate(JOINTS):
            for field in ("rotation", "elastic", "torque"):
                assert joints["joints"][name][field] == step[f"joint_{field}"][j].tolist()
        assert trace["/solver/stats"][k][1] == {"t": TIMES[k], **step["stats"]}


def test_caller_error_keeps_the_steps_written(tmp_path: Path) -> None:
    """A simulation failing part-way still leaves a finished, readable trace (replacing the old)."""
    path = tmp_path / "trace.mcap"
    path.write_bytes(b"previous run")
    rng = np.random.default_rng(1)
    with (
        pytest.raises(RuntimeError, match="diverged"),
        TraceWriter(path, BONES, PARENTS, JOINTS) as w,
    ):
        w.write_step(0.0, **step_inputs(rng, 0))
        w.write_step(DT, **step_inputs(rng, 1))
        raise RuntimeError("diverged")
    trace = read_trace(path)
    assert {topic: len(msgs) for topic, msgs in trace.items()} == dict.fromkeys(STEP_CHANNELS, 2)
    assert [p.name for p in tmp_path.iterdir()] == ["trace.mcap"]


def test_nan_raises_and_writes_nothing_of_that_step(tmp_path: Path) -> None:
    path = tmp_path / "trace.mcap"
    rng = np.random.default_rng(2)
    with TraceWriter(path, BONES, PARENTS, JOINTS) as writer:
        writer.write_step(0.0, **step_inputs(rng, 0))
        for field in ("joint_torque", "bone_head", "bone_quat"):
            bad = step_inputs(rng, 1)
            bad[field][1, 0] = np.nan
            with pytest.raises(ValueError, match="Out of range float"):
                writer.write_step(DT, **bad)
        bad = step_inputs(rng, 1)
        bad["stats"]["residual"] = float("inf")
        with pytest.raises(ValueError):
            writer.write_step(DT, **bad)
        with pytest.raises(ValueError):
            writer.write("/solver/stats", DT, {"t": DT, "residual": np.float64("nan")})
        writer.write_step(2 * DT, **step_inputs(rng, 2))
    times = {topic: [t for t, _ in msgs] for topic, msgs in read_trace(path).items()}
    assert times == {topic: [0, 20_000_000] for topic in STEP_CHANNELS}


def test_time_must_not_go_backwards_across_topics(tmp_path: Path) -> None:
    rng = np.random.default_rng(3)
    with TraceWriter(tmp_path / "trace.mcap", BONES, PARENTS, JOINTS) as writer:
        writer.add_channel("/events", "puppetcli.Event", {"type": "object"})
        writer.write_step(0.02, **step_inputs(rng, 0))
        writer.write("/events", 0.02, {"what": "same time is fine"})
        with pytest.raises(ValueError, match="backwards"):
            writer.write("/events", 0.01, {"what": "late"})
        with pytest.raises(ValueError, match="backwards"):
            writer.write_step(0.015, **step_inputs(rng, 1))
        for bad_time in (-0.1, float("nan"), float("inf")):
            with pytest.raises(ValueError, match="finite and non-negative"):
                writer.write("/events", bad_time, {})


def test_generic_channels(tmp_path: Path) -> None:
    """Later channels (device pose, wrench, key events) go through add_channel and write."""
    path = tmp_path / "trace.mcap"
    pose = {
        "timestamp": {"sec": 0, "nsec": 5},
        "frame_id": "puppet",
        "pose": {
            "position": {"x": 1.0, "y": 2.0, "z": 3.0},
            "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
        },
    }
    with TraceWriter(path, BONES, PARENTS, JOINTS) as writer:
        writer.add_channel(
            "/device/pose", "foxglove.PoseInFrame", load_schema("foxglove.PoseInFrame")
        )
        writer.add_channel(
            "/device/pose2", "foxglove.PoseInFrame", load_schema("foxglove.PoseInFrame")
        )
        with pytest.raises(ValueError, match="already exists"):
            writer.add_channel("/tf", "foxglove.FrameTransforms", {})
        with pytest.raises(ValueError, match="other content"):
            writer.add_channel("/x", "foxglove.PoseInFrame", {"type": "object"})
        with pytest.raises(ValueError, match="unknown trace channel /nope"):
            writer.write("/nope", 0.0, {})
        writer.write("/device/pose", 5e-9, pose)
        writer.write("/device/pose2", 1e-8, {"numpy": np.arange(3.0), "n": np.int64(2)})
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    assert len(summary.schemas) == 5  # PoseInFrame registered once for two channels
    ((_, message),) = read_trace(path)["/device/pose"]
    assert message == pose and schema_errors(message, load_schema("foxglove.PoseInFrame")) == []
    assert read_trace(path)["/device/pose2"] == [(10, {"numpy": [0.0, 1.0, 2.0], "n": 2})]
    with pytest.raises(ValueError, match="closed"):
        writer.write("/device/pose", 1.0, pose)


@pytest.mark.parametrize(
    ("parents", "names", "match"),
    [
        ([-1, 0], BONES, "shape"),
        ([-1, 2, 1], BONES, "tree"),
        ([-1, 0, 3], BONES, "tree"),
        ([-1, 0, 1], ["hips", "hips", "head"], "unique"),
        ([-1, 0, 1], ["hips", "puppet", "head"], "unique"),
    ],
)
def test_skeleton_must_be_a_tree(tmp_path: Path, parents: list, names: list, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        TraceWriter(tmp_path / "trace.mcap", names, parents, JOINTS)
    assert list(tmp_path.iterdir()) == []


def test_step_shapes_and_stats_are_checked(tmp_path: Path) -> None:
    rng = np.random.default_rng(4)
    with TraceWriter(tmp_path / "trace.mcap", BONES, PARENTS, JOINTS) as writer:
        bad = step_inputs(rng, 0)
        bad["joint_elastic"] = np.zeros((3, 3))
        with pytest.raises(
            ValueError, match=r"joint_elastic has shape \(3, 3\), expected \(2, 3\)"
        ):
            writer.write_step(0.0, **bad)
        bad = step_inputs(rng, 0)
        del bad["stats"]["solver"]
        with pytest.raises(ValueError, match="lack solver"):
            writer.write_step(0.0, **bad)
        bad = step_inputs(rng, 0)
        bad["stats"]["t"] = 1.0
        with pytest.raises(ValueError, match="differs"):
            writer.write_step(0.0, **bad)


def test_read_trace_reports_damaged_files(written: tuple[Path, list], tmp_path: Path) -> None:
    path, _ = written
    data = path.read_bytes()
    damaged = tmp_path / "damaged.mcap"
    for content in (data[: len(data) // 2], b"not an mcap", b"", data[:-3]):
        damaged.write_bytes(content)
        with pytest.raises(
            TraceError, match=r"damaged\.mcap: not a readable MCAP trace: .+"
        ) as info:
            read_trace(damaged)
        assert "\n" not in str(info.value)
    with pytest.raises(TraceError, match="cannot read"):
        read_trace(tmp_path / "missing.mcap")


def test_unfinishable_trace_is_not_published(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """If finish() itself fails the file would be torn: the old output must stay."""
    path = tmp_path / "trace.mcap"
    path.write_bytes(b"previous run")
    writer = TraceWriter(path, BONES, PARENTS, JOINTS)
    monkeypatch.setattr(
        writer._writer, "finish", lambda: (_ for _ in ()).throw(OSError("disk full"))
    )
    with pytest.raises(OSError, match="disk full"):
        writer.close()
    assert path.read_bytes() == b"previous run"
    assert [p.name for p in tmp_path.iterdir()] == ["trace.mcap"]


def test_third_party_jsonschema_agrees_when_installed(written: tuple[Path, list]) -> None:
    """Cross-check with the jsonschema package if the environment happens to have it."""
    jsonschema = pytest.importorskip("jsonschema")
    path, _ = written
    with open(path, "rb") as f:
        for schema, _, message in make_reader(f).iter_messages():
            jsonschema.validate(json.loads(message.data), json.loads(schema.data))
