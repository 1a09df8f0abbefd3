"""Session files (MCAP): what a SPIDAR-G device recorded, written and read back with checks.

Layout (docs/sessions.md): one metadata record ``puppetcli.mcap.session`` (device preset,
calibration, workspace mapping, run settings; values are JSON text) and JSON channels
with JSON-Schema schemas: ``/spidar/counts`` (puppetcli.SpidarCounts, one message per
1 kHz tick), ``/spidar/buttons`` (puppetcli.SpidarButton), optionally ``/spidar/pose``
(puppetcli.SpidarPose) and ``/script/events`` (puppetcli.SpidarScriptEvent).  Written
chunked, indexed, zstd, data CRCs on, log time = device time in integer ns,
non-decreasing across topics, atomically.

Reading checks everything a replay relies on; each problem is one ``SessionError``:
``<file>: <where>: expected …, got …``.
"""

from __future__ import annotations

import json
import os
import struct
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Channel, Message, Metadata, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer
from zstandard import ZstdError

from puppetcli.errors import SessionError, shown
from puppetcli.jsontext import json_bytes
from puppetcli.mcap.trace import library_name, load_schema
from puppetcli.outputs import atomic_path
from puppetcli.spidar import DeviceError, DevicePreset, preset, preset_from_text, preset_to_yaml
from puppetcli.yamldoc import LARGEST, SMALLEST
from solver import quat

__all__ = [
    "CHANNELS",
    "METADATA_NAME",
    "Event",
    "Session",
    "Workspace",
    "is_session",
    "read_session",
    "write_session",
]

FORMAT_VERSION = "3"  # 2 added the touch and undo buttons, 3 the pin button (docs/sessions.md)
FORMATS_READ = ("1", "2", "3")
METADATA_NAME = "puppetcli.mcap.session"
TICK = 1e-3  # s: the device's servo and pose-update period
CHANNELS = {
    "/spidar/counts": "puppetcli.SpidarCounts",
    "/spidar/buttons": "puppetcli.SpidarButton",
    "/spidar/pose": "puppetcli.SpidarPose",
    "/script/events": "puppetcli.SpidarScriptEvent",
}
READ_ERRORS = (McapError, ZstdError, struct.error, EOFError, ValueError, MemoryError, KeyError)


@dataclass(frozen=True)
class Workspace:
    """Device → world: p_world = offset + scale·R p_device, q_world = q ⊗ q_device ⊗ q⁻¹.

    offset (3,) m: world position of the device's home; scale: world metres per device
    metre (> 0); orientation (4,) (w, x, y, z): the device frame's rotation in the world
    (identity: device axes = world axes); fitted: chosen by the recorder, not the script.
    """

    offset: np.ndarray
    scale: float
    orientation: np.ndarray = field(default_factory=lambda: quat.IDENTITY.copy())
    fitted: bool = False

    def world_from_device(self, pos: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World poses (…,3), (…,4) of device poses."""
        r = self.orientation
        world = self.offset + self.scale * quat.rotate(r, np.asarray(pos, float))
        return world, quat.mul(quat.mul(r, q), quat.conj(r))

    def device_from_world(self, pos: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Device poses (…,3), (…,4) of world poses (the inverse map)."""
        r_inv = quat.conj(self.orientation)
        device = quat.rotate(r_inv, (np.asarray(pos, float) - self.offset) / self.scale)
        return device, quat.mul(quat.mul(r_inv, q), self.orientation)

    def to_json(self) -> dict:
        return {
            "offset": self.offset.tolist(),
            "scale": self.scale,
            "orientation": self.orientation.tolist(),
            "fitted": self.fitted,
        }


@dataclass(frozen=True)
class Event:
    """A button or script event: t (s), topic, index (in its channel), the decoded message."""

    t: float
    topic: str
    index: int
    message: dict


@dataclass(frozen=True)
class Session:
    """A recording.

    preset: the device.  home_counts (n,) int: counter values at home (calibration).
    workspace: device → world.  settings: the run's settings (h, duration, gravity, solver,
    pointer, haptics; keys optional).  recorder: free-form provenance.
    tick_time (T,) s and counts (T, n) int64: one row per device tick (None if absent).
    pose_time (P,), pose_pos (P,3), pose_quat (P,4): poses stored directly (or None).
    events: buttons and script events in file order.
    complete: False when the file ended abruptly (no summary: a killed recording), read as
    far as its last whole chunk.
    """

    preset: DevicePreset
    workspace: Workspace
    home_counts: np.ndarray
    settings: dict = field(default_factory=dict)
    recorder: dict = field(default_factory=dict)
    tick_time: np.ndarray | None = None
    counts: np.ndarray | None = None
    pose_time: np.ndarray | None = None
    pose_pos: np.ndarray | None = None
    pose_quat: np.ndarray | None = None
    events: tuple[Event, ...] = ()
    source: str = "<session>"
    complete: bool = True

    @property
    def end_time(self) -> float:
        """The last time anything happened (s)."""
        times = [e.t for e in self.events]
        for t in (self.tick_time, self.pose_time):
            if t is not None and len(t):
                times.append(float(t[-1]))
        return max(times, default=0.0)


# --- writing -----------------------------------------------------------------------------


def _metadata(session: Session) -> dict[str, str]:
    dev = session.preset
    meta = {"format": FORMAT_VERSION, "device": dev.name}
    if not _is_builtin(dev):
        meta["preset"] = preset_to_yaml(dev)
    calibration = {"home_counts": session.home_counts.tolist(), "tick": TICK}
    meta["calibration"] = json.dumps(calibration)
    meta["workspace"] = json.dumps(session.workspace.to_json())
    meta["settings"] = json.dumps(session.settings, allow_nan=False)
    meta["recorder"] = json.dumps(session.recorder, allow_nan=False)
    return meta


def _is_builtin(dev: DevicePreset) -> bool:
    try:
        known = preset(dev.name)
    except DeviceError:
        return False
    same = known.t_min == dev.t_min and known.t_max == dev.t_max
    for name in ("motor_pos", "grip_attach", "metres_per_count"):
        same = same and np.array_equal(getattr(known, name), getattr(dev, name))
    return same


def _messages(session: Session) -> list[tuple[int, int, str, dict]]:
    """(ns, order, topic, message) of every message, sorted by time then recording order."""
    out: list[tuple[int, int, str, dict]] = []
    if session.counts is not None:
        for t, row in zip(session.tick_time, session.counts, strict=True):
            out.append((_ns(t), len(out), "/spidar/counts", {"t": float(t), "counts": row}))
    if session.pose_pos is not None:
        for t, p, q in zip(session.pose_time, session.pose_pos, session.pose_quat, strict=True):
            message = {"t": float(t), "position": p, "orientation": q}
            out.append((_ns(t), len(out), "/spidar/pose", message))
    for event in session.events:
        out.append((_ns(event.t), len(out), event.topic, event.message))
    return sorted(out, key=lambda item: (item[0], item[1]))


def _ns(t: float) -> int:
    return round(float(t) * 1e9)


def write_session(path: Path, session: Session) -> None:
    """Write ``session`` to ``path`` atomically (MCAP, see the module docstring)."""
    messages = _messages(session)  # built (and NaN-checked) before any file is touched
    encoded = [(ns, topic, json_bytes(message)) for ns, _, topic, message in messages]
    topics = [t for t in CHANNELS if any(topic == t for _, topic, _ in encoded)]
    with atomic_path(Path(path)) as tmp, open(tmp, "wb") as f:
        writer = SessionWriter(f, session, topics)
        try:
            for ns, topic, data in encoded:
                writer.add_encoded(topic, ns, data)
        finally:
            writer.finish()


class SessionWriter:
    """Writes a session to an open binary file as it comes: header, channels and the
    ``puppetcli.mcap.session`` metadata first, then messages in time order (chunked, indexed,
    zstd, data CRCs).  ``flush`` closes the chunk in progress and syncs the file, so a
    recording killed after it still holds everything up to it (``read_session`` reads
    such a file without its summary); ``finish`` writes the summary.

    topics: the session channels to register (``/spidar/buttons`` always is); extra:
    further topic → schema name (e.g. the haptic channels of a live recording).
    """

    def __init__(
        self, f, session: Session, topics: Sequence[str], extra: dict[str, str] | None = None
    ) -> None:
        self._file = f
        self._writer = Writer(f, compression=CompressionType.ZSTD, enable_data_crcs=True)
        self._writer.start(profile="", library=library_name())
        names = {t: CHANNELS[t] for t in CHANNELS if t in topics or t == "/spidar/buttons"}
        names |= extra or {}
        self._channel: dict[str, int] = {}
        for topic, name in names.items():
            data = json.dumps(load_schema(name), separators=(",", ":")).encode()
            schema_id = self._writer.register_schema(name, "jsonschema", data)
            self._channel[topic] = self._writer.register_channel(topic, "json", schema_id)
        self._writer.add_metadata(METADATA_NAME, _metadata(session))
        self._sequence = dict.fromkeys(self._channel, 0)

    def add(self, topic: str, t: float, message: dict) -> None:
        """Append one message at device time ``t`` (s; never before the previous one)."""
        self.add_encoded(topic, _ns(t), json_bytes(message))

    def add_encoded(self, topic: str, ns: int, data: bytes) -> None:
        self._writer.add_message(self._channel[topic], ns, data, ns, self._sequence[topic])
        self._sequence[topic] += 1

    def count(self, topic: str) -> int:
        """Messages written to ``topic`` so far."""
        return self._sequence[topic]

    def add_metadata(self, name: str, values: dict[str, str]) -> None:
        self._writer.add_metadata(name, values)

    def flush(self) -> None:
        """Close the chunk in progress and push everything to the disk."""
        self._writer.flush()
        os.fsync(self._file.fileno())

    def finish(self) -> None:
        """Write the summary and footer and sync; the file is then complete."""
        self._writer.finish()
        self._file.flush()
        os.fsync(self._file.fileno())


# --- reading -----------------------------------------------------------------------------


def read_session(path: Path) -> Session:
    """Read and check a session file; raises ``SessionError`` (one line) on any problem.

    A file without its summary (a recording that was killed) is read record by record up
    to its last whole chunk; the Session then says ``complete=False``.
    """
    path = Path(path)
    try:
        with open(path, "rb") as f:
            try:
                meta, summary, raw = _read_indexed(path, f)
                complete = True
            except READ_ERRORS as exc:
                f.seek(0)
                meta, summary, raw = _read_records(path, f, exc)
                complete = False
    except OSError as exc:
        raise SessionError(f"{path}: cannot read: {exc.strerror}") from exc
    _check_channels(path, summary)
    return _build(path, meta, raw, complete)


def is_session(path: Path) -> bool:
    """Whether ``path`` is an MCAP file with a ``puppetcli.mcap.session`` record (a recorded
    session, not a trace); False for a file that is neither readable nor one."""
    try:
        with open(path, "rb") as f:
            try:
                return METADATA_NAME in [m.name for m in make_reader(f).iter_metadata()]
            except READ_ERRORS:  # no summary (a killed recording): its record comes first
                f.seek(0)
                for record in StreamReader(f, emit_chunks=True).records:
                    if isinstance(record, Metadata):
                        return record.name == METADATA_NAME
    except (OSError, *READ_ERRORS):
        pass
    return False


def _read_indexed(path: Path, f) -> tuple[dict[str, str], Any, list]:
    reader = make_reader(f, validate_crcs=True)
    summary = reader.get_summary()
    if summary is None:
        raise McapError("no summary")
    meta = _read_metadata(path, reader.iter_metadata())
    return meta, summary, list(reader.iter_messages(log_time_order=False))


def _read_records(path: Path, f, first: Exception) -> tuple[dict[str, str], Any, list]:
    """The records of a file whose end is missing, in file order, up to the first bad one."""
    schemas, channels, metadata, raw = {}, {}, [], []
    try:
        for record in StreamReader(f, validate_crcs=True).records:
            if isinstance(record, Schema):
                schemas[record.id] = record
            elif isinstance(record, Channel):
                channels[record.id] = record
            elif isinstance(record, Metadata):
                metadata.append(record)
            elif isinstance(record, Message) and record.channel_id in channels:
                channel = channels[record.channel_id]
                raw.append((schemas.get(channel.schema_id), channel, record))
    except READ_ERRORS:
        pass  # the cut: keep what came before it
    if not metadata or not raw:
        what = str(first) or type(first).__name__
        raise SessionError(
            f"{path}: expected a complete MCAP file, got a truncated or corrupt one ({what})"
        )
    return _read_metadata(path, metadata), SimpleNamespace(schemas=schemas, channels=channels), raw


def _read_metadata(path: Path, records) -> dict[str, str]:
    for record in records:
        if record.name == METADATA_NAME:
            return dict(record.metadata)
    raise SessionError(
        f"{path}: metadata: expected a '{METADATA_NAME}' record (device, calibration, "
        "workspace), got none"
    )


def _check_channels(path: Path, summary) -> None:
    topics = {c.topic: c for c in summary.channels.values()}
    if "/spidar/buttons" not in topics or not ({"/spidar/counts", "/spidar/pose"} & set(topics)):
        have = ", ".join(sorted(topics)) or "none"
        raise SessionError(
            f"{path}: channels: expected /spidar/counts (or /spidar/pose) and /spidar/buttons, "
            f"got {have}"
        )
    for topic, channel in topics.items():
        if topic not in CHANNELS:
            continue  # other channels are allowed and ignored
        schema = summary.schemas.get(channel.schema_id)
        got = "no schema" if schema is None else f"'{schema.name}' ({schema.encoding})"
        if schema is None or schema.name != CHANNELS[topic] or schema.encoding != "jsonschema":
            raise SessionError(
                f"{path}: channel {topic}: expected schema '{CHANNELS[topic]}' (jsonschema), "
                f"got {got}"
            )
        if channel.message_encoding != "json":
            raise SessionError(
                f"{path}: channel {topic}: expected message encoding 'json', "
                f"got '{channel.message_encoding}'"
            )


def _meta_json(path: Path, meta: dict[str, str], key: str, default: Any) -> Any:
    if key not in meta:
        if default is None:
            raise SessionError(f"{path}: metadata.{key}: expected a value, got none")
        return default
    try:
        return json.loads(meta[key])
    except (ValueError, RecursionError) as exc:
        raise SessionError(
            f"{path}: metadata.{key}: expected JSON, got {shown(meta[key])}"
        ) from exc


def _device(path: Path, meta: dict[str, str]) -> DevicePreset:
    try:
        if "preset" in meta:
            return preset_from_text(meta["preset"], f"{path}: metadata.preset")
        if "device" not in meta:
            raise SessionError(f"{path}: metadata.device: expected a preset name, got none")
        return preset(meta["device"])
    except DeviceError as exc:
        raise SessionError(f"{path}: metadata.device: {exc}") from exc


def _workspace(path: Path, meta: dict[str, str]) -> Workspace:
    ws = _meta_json(path, meta, "workspace", None)
    try:
        offset = np.array(ws["offset"], dtype=float).reshape(3)
        scale = float(ws["scale"])
        orientation = np.array(ws.get("orientation", [1, 0, 0, 0]), dtype=float).reshape(4)
    except (TypeError, KeyError, ValueError) as exc:
        raise SessionError(
            f"{path}: metadata.workspace: expected {{offset: [x, y, z], scale: s, "
            f"orientation: [w, x, y, z]}}, got {shown(meta['workspace'])}"
        ) from exc
    finite = np.all(np.abs(offset) <= LARGEST) and SMALLEST <= scale <= LARGEST
    norm = float(np.linalg.norm(orientation)) if np.all(np.abs(orientation) <= 2.0) else 0.0
    if not (finite and 0.5 < norm < 2.0):
        raise SessionError(
            f"{path}: metadata.workspace: expected a finite offset, scale > 0 and a unit "
            f"orientation, got {shown(meta['workspace'])}"
        )
    return Workspace(offset, scale, orientation / norm, bool(ws.get("fitted", False)))


def _home_counts(path: Path, meta: dict[str, str], n: int) -> np.ndarray:
    calibration = _meta_json(path, meta, "calibration", {"home_counts": [0] * n})
    home = calibration.get("home_counts") if isinstance(calibration, dict) else None
    if not (isinstance(home, list) and len(home) == n and all(_is_int(c) for c in home)):
        raise SessionError(
            f"{path}: metadata.calibration.home_counts: expected {n} integers, got {shown(home)}"
        )
    return np.array(home, dtype=np.int64)


def _is_int(value: Any) -> bool:
    """An encoder count: an integer of a 32-bit counter."""
    return isinstance(value, int) and not isinstance(value, bool) and abs(value) < 2**31


def _build(path: Path, meta: dict[str, str], raw: list, complete: bool) -> Session:
    version = meta.get("format", "1")
    if version not in FORMATS_READ:
        raise SessionError(
            f"{path}: metadata.format: expected {' or '.join(FORMATS_READ)} (a newer puppetcli "
            f"wrote this file), got {shown(version)}"
        )
    dev = _device(path, meta)
    columns: dict[str, list] = {topic: [] for topic in CHANNELS}
    events: list[Event] = []
    last_ns = 0
    for _, channel, message in raw:
        topic = channel.topic
        if topic not in CHANNELS:
            continue
        index = len(columns[topic])
        where = f"{path}: {topic}[{index}]"
        if message.log_time < last_ns:
            raise SessionError(
                f"{where}: log time: expected time never to go backwards (>= {last_ns} ns), "
                f"got {message.log_time} ns"
            )
        last_ns = message.log_time
        value = parse_message(where, topic, message.data, message.log_time, dev.n_strings)
        columns[topic].append(value)
        if topic in ("/spidar/buttons", "/script/events"):
            events.append(Event(value["t"], topic, index, value))
    counts, poses = columns["/spidar/counts"], columns["/spidar/pose"]
    if not counts and not poses:
        raise SessionError(f"{path}: /spidar/counts: expected at least one tick, got none")
    return Session(
        preset=dev,
        workspace=_workspace(path, meta),
        home_counts=_home_counts(path, meta, dev.n_strings),
        settings=_meta_json(path, meta, "settings", {}),
        recorder=_meta_json(path, meta, "recorder", {}),
        tick_time=np.array([c["t"] for c in counts]) if counts else None,
        counts=np.array([c["counts"] for c in counts], dtype=np.int64) if counts else None,
        pose_time=np.array([p["t"] for p in poses]) if poses else None,
        pose_pos=np.array([p["position"] for p in poses]) if poses else None,
        pose_quat=quat.normalize(np.array([p["orientation"] for p in poses])) if poses else None,
        events=tuple(events),
        source=str(path),
        complete=complete,
    )


# --- message checks ------------------------------------------------------------------------

_BUTTON_KEYS = {"bone": str, "label": str, "gains": dict, "line": int, "orient": bool}


def parse_message(where: str, topic: str, data: bytes, log_ns: int, n: int) -> dict:
    """Decode one JSON message and check the fields a replay uses (one error line each)."""
    try:
        value = json.loads(data)
    except (ValueError, RecursionError) as exc:
        raise SessionError(f"{where}: expected a JSON message, got {shown(data[:40])}") from exc
    if not isinstance(value, dict):
        raise SessionError(f"{where}: expected a JSON object, got {type(value).__name__}")
    t = value.get("t")
    if not isinstance(t, int | float) or isinstance(t, bool) or abs(t * 1e9 - log_ns) > 1e3:
        raise SessionError(
            f"{where}: t: expected the message's log time {log_ns * 1e-9:.9g} s, got {shown(t)}"
        )
    if topic == "/spidar/counts":
        counts = value.get("counts")
        if not (isinstance(counts, list) and len(counts) == n and all(map(_is_int, counts))):
            got = f"{len(counts)} values" if isinstance(counts, list) else repr(counts)
            raise SessionError(
                f"{where}: counts: expected {n} integers (one per string), got {got}"
            )
    elif topic == "/spidar/pose":
        _vector(where, value, "position", 3)
        _vector(where, value, "orientation", 4)
    elif topic == "/spidar/buttons":
        _button(where, value)
    else:
        if value.get("action") not in ("push", "expect"):
            raise SessionError(
                f"{where}: action: expected 'push' or 'expect', got {shown(value.get('action'))}"
            )
    return value


def _vector(where: str, value: dict, key: str, size: int) -> None:
    v = value.get(key)
    ok = isinstance(v, list) and len(v) == size
    if not (ok and all(isinstance(x, int | float) and np.isfinite(x) for x in v)):
        raise SessionError(f"{where}: {key}: expected {size} finite numbers, got {shown(v)}")


def _button(where: str, value: dict) -> None:
    if not isinstance(value.get("button"), str):
        raise SessionError(
            f"{where}: button: expected a button name, got {shown(value.get('button'))}"
        )
    if value.get("state") not in ("down", "up"):
        raise SessionError(
            f"{where}: state: expected 'down' or 'up', got {shown(value.get('state'))}"
        )
    for key, kind in _BUTTON_KEYS.items():
        if key in value and not isinstance(value[key], kind):
            raise SessionError(
                f"{where}: {key}: expected a {kind.__name__}, got {shown(value[key])}"
            )
    if "point" in value:
        _vector(where, value, "point", 3)
