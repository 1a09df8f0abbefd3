"""trace.mcap: a Foxglove-viewable record of a simulation, one group of messages per step.

MCAP written with the official ``mcap`` package: chunked, zstd, fully indexed,
data CRCs on; JSON messages on channels whose schemas are JSON Schemas
(``jsonschema``), so Foxglove recognises ``foxglove.*`` types by name.
``log_time = publish_time = round(t·1e9)`` ns of simulated time, non-decreasing
across all topics.  The file is written under a temporary name and published
when the writer closes, also when the caller fails part-way (the steps captured
so far are kept, see ``outputs.atomic_path(keep_on_error=True)``).

Frames.  Our world is Y-up; Foxglove's 3D panel is Z-up.  ``/tf`` therefore
holds ``world → puppet``, +90° about X (maps +Y to +Z), then one frame per bone,
named after it, with origin at the bone head and orientation the bone's world
rotation q_b.  A bone's transform is given in its parent's frame (root: in
``puppet``):  translation = R_pᵀ (head_b − head_p),  rotation = q_p⁻¹ ⊗ q_b, so
p_parent = translation + rotation · p_child, as FrameTransform defines it.
Foxglove quaternions are {x, y, z, w}, scalar last.
"""

from __future__ import annotations

import importlib.metadata
import importlib.resources
import json
import math
import os
import struct
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer
from zstandard import ZstdError

from puppetcli.errors import PuppetError, shown
from puppetcli.jsontext import json_bytes
from puppetcli.mcap.template import MessageTemplate, Slot, slots
from puppetcli.outputs import atomic_path
from solver import quat

__all__ = [
    "PUPPET_FRAME",
    "STEP_CHANNELS",
    "TIME_SLOTS",
    "WORLD_FRAME",
    "TraceError",
    "TraceWriter",
    "bones_scene",
    "clock",
    "foxglove_time",
    "frame_transforms",
    "load_schema",
    "ns_from_seconds",
    "read_trace",
    "relative_frames",
    "scene_update",
]

WORLD_FRAME = "world"
PUPPET_FRAME = "puppet"
# +90° about X, (w, x, y, z): the Y-up puppet frame inside Foxglove's Z-up world.
Y_UP_IN_Z_UP = np.array([math.sqrt(0.5), math.sqrt(0.5), 0.0, 0.0])
JOINT_SPHERE_DIAMETER = 0.02  # m: marks a bone head without hiding a doll-sized bone
BONE_LINE_PIXELS = 2.0  # screen-space line width (scale_invariant)
BONE_COLOR = {"r": 0.85, "g": 0.75, "b": 0.55, "a": 1.0}
JOINT_COLOR = {"r": 0.75, "g": 0.25, "b": 0.2, "a": 1.0}
_IDENTITY_POSE = {
    "position": {"x": 0.0, "y": 0.0, "z": 0.0},
    "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
}
# A Foxglove ``time`` in a message template, and the groups its numbers (``clock``) fill.
TIME_SLOTS = ({"sec": Slot("sec"), "nsec": Slot("nsec")}, [("sec", 1), ("nsec", 1)])
_STATS_KEYS = ("rows", "contacts", "iterations", "residual", "solver")
STEP_CHANNELS = {
    "/tf": "foxglove.FrameTransforms",
    "/puppet/bones": "foxglove.SceneUpdate",
    "/puppet/joints": "puppetcli.Joints",
    "/solver/stats": "puppetcli.SolverStats",
}


class TraceError(PuppetError):
    """A trace file cannot be read."""


def load_schema(name: str) -> dict:
    """The JSON Schema called ``name`` (e.g. ``foxglove.SceneUpdate``) in puppetcli/schemas."""
    resource = importlib.resources.files("puppetcli") / "schemas" / f"{name}.json"
    return json.loads(resource.read_text(encoding="utf-8"))


def library_name() -> str:
    """The MCAP header's library string: ``puppetcli <installed version>``."""
    try:
        version = importlib.metadata.version("puppetcli")
    except importlib.metadata.PackageNotFoundError:
        version = "0.1.0"
    return f"puppetcli {version}"


def ns_from_seconds(t: float) -> int:
    """Simulated time (s) as MCAP integer nanoseconds; rejects negative or non-finite times."""
    if not math.isfinite(t) or t < 0.0:
        raise ValueError(f"trace time must be finite and non-negative, got {shown(t)}")
    return round(t * 1e9)


def foxglove_time(ns: int) -> dict:
    """Foxglove ``time`` of integer nanoseconds."""
    return dict(zip(("sec", "nsec"), clock(ns), strict=True))


def clock(ns: int) -> tuple[int, int]:
    """(seconds, nanoseconds) of integer nanoseconds: the numbers of a Foxglove ``time``, as
    a message template (puppetcli.mcap.template) takes them for ``TIME_SLOTS``."""
    return divmod(ns, 1_000_000_000)


def _vec3s(points: np.ndarray) -> list[dict]:
    """Foxglove vectors of the rows of ``points`` (k, 3) (one ``tolist`` for them all)."""
    return [{"x": x, "y": y, "z": z} for x, y, z in np.reshape(points, (-1, 3)).tolist()]


def _quats_xyzw(q: np.ndarray) -> list[dict]:
    """Foxglove quaternions (scalar last) of our (w, x, y, z) rows of ``q`` (k, 4)."""
    return [{"x": x, "y": y, "z": z, "w": w} for w, x, y, z in np.reshape(q, (-1, 4)).tolist()]


def frame_transforms(
    ns: int, bone_names: Sequence[str], bone_parents: np.ndarray, head: np.ndarray, rot: np.ndarray
) -> dict:
    """``foxglove.FrameTransforms``: world → puppet, then each bone in its parent's frame."""
    move, turn = relative_frames(bone_parents, head, rot)
    return _transforms_message(foxglove_time(ns), bone_names, bone_parents, move, turn)


def relative_frames(
    bone_parents: np.ndarray, head: np.ndarray, rot: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(translations (..., nb+1, 3), rotations (..., nb+1, 4)) of world → puppet, then of
    each bone in its parent's frame (module docstring), for heads (..., nb, 3) and
    rotations (..., nb, 4) of any number of leading axes."""
    q = quat.normalize(rot)
    has_parent = (bone_parents >= 0)[:, None]
    parent = np.where(has_parent[:, 0], bone_parents, 0)
    q_parent = np.where(has_parent, q[..., parent, :], quat.IDENTITY)
    head_parent = np.where(has_parent, head[..., parent, :], 0.0)
    q_parent_inv = quat.conj(q_parent)
    translation = quat.rotate(q_parent_inv, head - head_parent)
    rotation = quat.mul(q_parent_inv, q)
    lead = head.shape[:-2]
    return (
        np.concatenate((np.zeros((*lead, 1, 3)), translation), axis=-2),
        np.concatenate((np.broadcast_to(Y_UP_IN_Z_UP, (*lead, 1, 4)), rotation), axis=-2),
    )


def _transforms_message(
    stamp: dict, bone_names: Sequence[str], bone_parents: np.ndarray, move, turn
) -> dict:
    """``foxglove.FrameTransforms`` of ``relative_frames``' translations and rotations."""
    parents = [PUPPET_FRAME if p < 0 else bone_names[p] for p in bone_parents.tolist()]
    frames = zip([WORLD_FRAME, *parents], [PUPPET_FRAME, *bone_names], strict=True)
    return {
        "transforms": [
            {"timestamp": stamp, "parent_frame_id": parent, "child_frame_id": child,
             "translation": move, "rotation": turn}
            for (parent, child), move, turn in zip(frames, _vec3s(move), _quats_xyzw(turn),
                                                   strict=True)
        ]
    }  # fmt: skip


def bones_scene(ns: int, head: np.ndarray, tail: np.ndarray) -> dict:
    """``foxglove.SceneUpdate``: in ``puppet``, a LINE_LIST head→tail per bone and head balls."""
    return _bones_message(foxglove_time(ns), head, tail)


def _bones_message(stamp: dict, head: np.ndarray, tail: np.ndarray) -> dict:
    segments = np.stack((head, tail), axis=1)
    diameter = JOINT_SPHERE_DIAMETER
    return scene_update(stamp, "bones", segments, head, BONE_COLOR, JOINT_COLOR, diameter)


def scene_update(
    stamp: dict,
    entity_id: str,
    segments: np.ndarray,
    centres: np.ndarray,
    line_color: dict,
    sphere_color: dict,
    diameter: float,
) -> dict:
    """``foxglove.SceneUpdate`` at the Foxglove time ``stamp``: one entity in ``puppet``,
    segments (k,2,3) and balls (m,3)."""
    line = {
        "type": 2,  # LINE_LIST: points pair up as (start, end)
        "pose": _IDENTITY_POSE,
        "thickness": BONE_LINE_PIXELS,
        "scale_invariant": True,
        "points": _vec3s(segments),
        "color": line_color,
        "colors": [],
        "indices": [],
    }
    size = _vec3s(np.full(3, diameter))[0]
    spheres = [
        {"pose": {**_IDENTITY_POSE, "position": p}, "size": size, "color": sphere_color}
        for p in _vec3s(centres)
    ]
    entity = {
        "timestamp": stamp,
        "frame_id": PUPPET_FRAME,
        "id": entity_id,
        "lifetime": {
            "sec": 0,
            "nsec": 0,
        },  # forever; the next message's entity replaces it (same id)
        "frame_locked": True,
        "metadata": [],
        "arrows": [],
        "cubes": [],
        "spheres": spheres,
        "cylinders": [],
        "lines": [line] if len(segments) else [],
        "triangles": [],
        "texts": [],
        "models": [],
    }
    return {"deletions": [], "entities": [entity]}


def _check_skeleton(bone_names: Sequence[str], bone_parents: Sequence[int]) -> np.ndarray:
    """Bone parents as an int array, checked to form a tree (Foxglove's TF graph must be one)."""
    parents = np.asarray(bone_parents, dtype=int)
    nb = len(bone_names)
    if parents.shape != (nb,):
        raise ValueError(f"bone_parents has shape {parents.shape}, expected ({nb},)")
    if len(set(bone_names)) != nb or {WORLD_FRAME, PUPPET_FRAME} & set(bone_names):
        raise ValueError(f"bone names must be unique and not '{WORLD_FRAME}'/'{PUPPET_FRAME}'")
    for i in range(nb):
        j, hops = i, 0
        while j >= 0:
            if j >= nb or parents[j] < -1 or hops > nb:
                raise ValueError(f"bone_parents does not form a tree (bone {bone_names[i]!r})")
            j, hops = parents[j], hops + 1
    return parents


def _rows(name: str, array: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """``array`` as floats, checked to have ``shape`` (the first axis: the steps)."""
    a = np.asarray(array, dtype=float)
    if a.shape != shape:
        raise ValueError(f"{name} has shape {a.shape[1:]}, expected {shape[1:]}")
    return a


class TraceWriter:
    """Writes trace.mcap step by step; use as a context manager (or call :meth:`close`).

    Registers the four step channels (``/tf``, ``/puppet/bones``, ``/puppet/joints``,
    ``/solver/stats``); :meth:`add_channel` adds others (device pose, wrench, key
    events) that :meth:`write` then fills.
    """

    def __init__(
        self,
        path: Path,
        bone_names: Sequence[str],
        bone_parents: Sequence[int],
        joint_names: Sequence[str],
    ) -> None:
        self.bone_names = list(bone_names)
        self.bone_parents = _check_skeleton(self.bone_names, bone_parents)
        self.joint_names = list(joint_names)
        self._schemas: dict[str, tuple[int, bytes]] = {}
        self._channels: dict[str, int] = {}
        self._sequence: dict[str, int] = {}
        self._last_ns = 0
        self._closed = False
        self._publisher = atomic_path(Path(path), keep_on_error=True)
        self._tmp = self._publisher.__enter__()
        try:
            # Outlives __init__: closed by close()/__exit__ after the MCAP is finished.
            self._file = open(self._tmp, "wb")  # noqa: SIM115
            self._writer = Writer(
                self._file, compression=CompressionType.ZSTD, enable_data_crcs=True
            )
            self._writer.start(profile="", library=library_name())
            for topic, schema_name in STEP_CHANNELS.items():
                self.add_channel(topic, schema_name, load_schema(schema_name))
        except BaseException as exc:
            self._discard(exc)
            raise
        self._templates = self._step_templates()

    def __enter__(self) -> TraceWriter:
        return self

    def __exit__(self, exc_type: type | None, exc: BaseException | None, tb: object) -> None:
        self._close(exc)

    def add_channel(self, topic: str, schema_name: str, schema: dict) -> None:
        """Add a JSON channel whose messages follow the JSON Schema ``schema`` (``schema_name``)."""
        self._check_open()
        if topic in self._channels:
            raise ValueError(f"trace channel {topic} already exists")
        data = json.dumps(schema, separators=(",", ":")).encode("utf-8")
        if schema_name not in self._schemas:
            schema_id = self._writer.register_schema(schema_name, "jsonschema", data)
            self._schemas[schema_name] = (schema_id, data)
        schema_id, known = self._schemas[schema_name]
        if known != data:
            raise ValueError(f"schema {schema_name} was already registered with other content")
        self._channels[topic] = self._writer.register_channel(topic, "json", schema_id)
        self._sequence[topic] = 0

    def write(self, topic: str, t: float, message: dict) -> None:
        """Write ``message`` on ``topic`` at simulated time ``t`` (s); numpy values are allowed."""
        self.write_encoded(topic, t, json_bytes(message))

    def write_encoded(self, topic: str, t: float, data: bytes) -> None:
        """Write the JSON message ``data`` (UTF-8) on ``topic`` at simulated time ``t`` (s)."""
        self._check_open()
        if topic not in self._channels:
            raise ValueError(f"unknown trace channel {topic}; known: {', '.join(self._channels)}")
        self._add(topic, self._check_time(t), data)

    def write_step(
        self,
        t: float,
        *,
        joint_rotation: np.ndarray,
        joint_elastic: np.ndarray,
        joint_torque: np.ndarray,
        bone_head: np.ndarray,
        bone_tail: np.ndarray,
        bone_quat: np.ndarray,
        stats: dict,
    ) -> None:
        """Write one step on the four step channels, all or nothing (shapes and NaN checked first).

        joint_* (njoint, 3): rotation vector from rest and elastic part q_sf (rad),
        rheology row force (N·m), in ``joint_names`` order.  bone_head/bone_tail
        (nbone, 3) world positions (m); bone_quat (nbone, 4) world rotations (w, x, y, z).
        stats: rows, contacts, iterations, residual, solver (see puppetcli.SolverStats).
        """
        arrays = (joint_rotation, joint_elastic, joint_torque, bone_head, bone_tail, bone_quat)
        self.write_steps([t], *(np.asarray(a, dtype=float)[None] for a in arrays), [stats])

    def write_steps(
        self,
        times: list[float],
        joint_rotation: np.ndarray,
        joint_elastic: np.ndarray,
        joint_torque: np.ndarray,
        bone_head: np.ndarray,
        bone_tail: np.ndarray,
        bone_quat: np.ndarray,
        stats: list[dict],
        then: Callable[[int], None] | None = None,
    ) -> None:
        """``write_step`` for k steps at once (the arrays with a first axis of k): the
        frames are computed together; a step that fails writes nothing of itself and
        leaves the steps before it written.  ``then(i)``, when given, runs after step i is
        written (to write the caller's messages of that step, in time order)."""
        self._check_open()
        k, nb, nj = len(times), len(self.bone_names), len(self.joint_names)
        head = _rows("bone_head", bone_head, (k, nb, 3))
        tail = _rows("bone_tail", bone_tail, (k, nb, 3))
        rot = _rows("bone_quat", bone_quat, (k, nb, 4))
        joints = np.concatenate(
            [_rows(name, a, (k, nj, 3)) for name, a in
             (("joint_rotation", joint_rotation), ("joint_elastic", joint_elastic),
              ("joint_torque", joint_torque))], axis=2,
        ).reshape(k, -1).tolist()  # fmt: skip
        move, turn = relative_frames(self.bone_parents, head, rot)
        move, turn = move.reshape(k, -1).tolist(), turn.reshape(k, -1).tolist()
        head, tail = head.reshape(k, -1).tolist(), tail.reshape(k, -1).tolist()
        tf, bones, joint = self._templates
        for i, t in enumerate(times):
            ns = self._check_time(t)
            stamp = clock(ns)
            encoded = {
                "/tf": tf.fill([*stamp, *move[i], *turn[i]]),
                "/puppet/bones": bones.fill([*stamp, *head[i], *tail[i]]),
                "/puppet/joints": joint.fill([t, *joints[i]]),
                "/solver/stats": json_bytes(_stats_message(t, stats[i])),
            }
            for topic, data in encoded.items():
                self._add(topic, ns, data)
            if then is not None:
                then(i)

    def _step_templates(self) -> tuple[MessageTemplate, MessageTemplate, MessageTemplate]:
        """Templates (puppetcli.mcap.template) of ``/tf``, ``/puppet/bones`` and
        ``/puppet/joints``, the numbers in the order ``write_step`` fills them."""
        nb, nj = len(self.bone_names), len(self.joint_names)
        stamp, time_groups = TIME_SLOTS
        move, turn = slots("move", (nb + 1, 3)), slots("turn", (nb + 1, 4))
        tf = _transforms_message(stamp, self.bone_names, self.bone_parents, move, turn)
        head, tail = slots("head", (nb, 3)), slots("tail", (nb, 3))
        bones = _bones_message(stamp, head, tail)
        joint = slots("joint", (nj, 3, 3))
        joints = self._joints_message(Slot("t"), joint[:, 0], joint[:, 1], joint[:, 2])
        return (
            MessageTemplate(tf, [*time_groups, ("move", move.size), ("turn", turn.size)]),
            MessageTemplate(bones, [*time_groups, ("head", head.size), ("tail", tail.size)]),
            MessageTemplate(joints, [("t", 1), ("joint", joint.size)]),
        )

    def close(self) -> None:
        """Finish the MCAP (summary, indexes, footer) and publish the file; idempotent."""
        self._close(None)

    def _joints_message(self, t, rotation, elastic, torque) -> dict:
        """``/puppet/joints`` at ``t``: (nj, 3) rotations, elastic parts and torques."""
        rows = zip(
            self.joint_names, rotation.tolist(), elastic.tolist(), torque.tolist(), strict=True
        )
        joints = {name: {"rotation": r, "elastic": e, "torque": f} for name, r, e, f in rows}
        return {"t": t, "joints": joints}

    def _check_open(self) -> None:
        if self._closed:
            raise ValueError("trace writer is closed")

    def _check_time(self, t: float) -> int:
        ns = ns_from_seconds(t)
        if ns < self._last_ns:
            raise ValueError(
                f"trace time went backwards: t = {t!r} s after {self._last_ns / 1e9!r} s"
            )
        return ns

    def _add(self, topic: str, ns: int, data: bytes) -> None:
        sequence = self._sequence[topic]
        self._writer.add_message(self._channels[topic], ns, data, ns, sequence)
        self._sequence[topic] = sequence + 1
        self._last_ns = ns

    def _close(self, error: BaseException | None) -> None:
        """Finish and publish; a caller's ``error`` is passed on so atomic_path keeps the file."""
        if self._closed:
            return
        self._closed = True
        try:
            self._writer.finish()
            self._file.flush()
            os.fsync(self._file.fileno())
            self._file.close()
        except BaseException as exc:
            self._discard(exc)  # an unfinished MCAP is unreadable: never publish it
            raise
        if error is None:
            self._publisher.__exit__(None, None, None)
        else:
            self._publisher.__exit__(type(error), error, error.__traceback__)

    def _discard(self, error: BaseException) -> None:
        """Drop the temporary file and leave any existing target untouched."""
        self._closed = True
        file = getattr(self, "_file", None)
        if file is not None:
            file.close()
        self._tmp.unlink(missing_ok=True)
        self._publisher.__exit__(type(error), error, error.__traceback__)


def _stats_message(t: float, stats: dict) -> dict:
    """The /solver/stats message: ``t`` first, then the caller's stats as given."""
    missing = [k for k in _STATS_KEYS if k not in stats]
    if missing:
        raise ValueError(f"solver stats lack {', '.join(missing)}")
    if "t" in stats and stats["t"] != t:
        raise ValueError(f"solver stats t = {stats['t']!r} differs from the step time {t!r}")
    return {"t": t, **{k: v for k, v in stats.items() if k != "t"}}


# What the mcap reader raises on damaged input (found by flipping every byte of a trace);
# MemoryError: a corrupt length can make it allocate absurd sizes (foxglove/mcap #1220).
_CORRUPT_ERRORS = (
    McapError,
    ValueError,
    EOFError,
    KeyError,
    OverflowError,
    MemoryError,
    struct.error,
    ZstdError,
)


def read_trace(path: Path) -> dict[str, list[tuple[int, dict]]]:
    """Every message of a trace, by topic, as (log_time ns, decoded JSON), in log-time order.

    Chunk CRCs are validated.  Unreadable or corrupt files raise :class:`TraceError`.
    """
    try:
        with open(path, "rb") as f:
            reader = make_reader(f, validate_crcs=True)
            summary = reader.get_summary()
            channels = summary.channels.values() if summary is not None else ()
            out: dict[str, list[tuple[int, dict]]] = {c.topic: [] for c in channels}
            for _schema, channel, message in reader.iter_messages(log_time_order=True):
                decoded = _decode(path, channel.topic, channel.message_encoding, message)
                out.setdefault(channel.topic, []).append((message.log_time, decoded))
    except OSError as exc:
        raise TraceError(f"{path}: cannot read: {exc.strerror or exc}") from exc
    except _CORRUPT_ERRORS as exc:
        reason = str(exc) or "unexpected end of file"
        raise TraceError(f"{path}: not a readable MCAP trace: {reason}") from exc
    return out


def _decode(path: Path, topic: str, encoding: str, message: Any) -> dict:
    if encoding != "json":
        raise TraceError(f"{path}: {topic}: expected json messages, got {shown(encoding)}")
    try:
        return json.loads(message.data)
    except (ValueError, RecursionError) as exc:
        raise TraceError(
            f"{path}: {topic} at log_time {message.log_time}: expected JSON, got {exc}"
        ) from exc
