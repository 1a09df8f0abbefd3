"""keyframes.json: the kept poses of a session, a stable contract read by other tools.

::

    {"rig": NAME,
     "keys": [{"time": s, "label": str, <extra fields...>,
               "bones": {BONE: {"head": [x, y, z],
                                "rotation": [w, x, y, z],
                                "local": [w, x, y, z]}}}]}

``head`` is the bone head in the Y-up world (m); ``rotation`` the bone's world
rotation relative to its rest orientation; ``local`` its joint rotation relative
to rest, in the parent's frame (the root's local equals its rotation).
Quaternions are unit, scalar first, with w ≥ 0 (a file with w < 0 reads as the same
rotation, negated).  Keys are strictly increasing in time and
every key holds the same bones.  Floats are written with ``repr`` precision, so
a read gives back the written values bit for bit; NaN is never written.
"""

from __future__ import annotations

import bisect
import json
import math
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NoReturn

import numpy as np

from puppetcli.errors import PuppetError, shown
from puppetcli.outputs import write_json_atomic
from puppetcli.yamldoc import LARGEST

__all__ = [
    "BonePose",
    "Keyframe",
    "KeyframeSet",
    "KeyframesError",
    "read_keyframes",
    "write_keyframes",
]

SAME_TIME = 1e-9  # s: keys closer than this are the same key
UNIT_TOLERANCE = 1e-6  # allowed | |q| - 1 | for a stored quaternion
_RESERVED = ("time", "label", "bones")
_VECTORS = (("head", 3), ("rotation", 4), ("local", 4))


class KeyframesError(PuppetError):
    """A keyframes file is unreadable or malformed."""


@dataclass(eq=False)
class BonePose:
    """One bone in a key: head (3,) m world; rotation, local (4,) unit (w, x, y, z) from rest,
    kept with w ≥ 0 (a quaternion given with w < 0 is negated: the same rotation)."""

    head: np.ndarray
    rotation: np.ndarray
    local: np.ndarray

    def __post_init__(self) -> None:
        # Copies: a key must not change when the simulation state it came from moves on.
        for name, n in _VECTORS:
            value = np.array(getattr(self, name), dtype=float)
            if value.shape != (n,):
                raise ValueError(f"BonePose.{name} has shape {value.shape}, expected ({n},)")
            if n == 4 and value[0] < 0.0:  # q and −q are one rotation: kept with w ≥ 0
                value = -value
            setattr(self, name, value)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, BonePose):
            return NotImplemented
        return all(np.array_equal(getattr(self, n), getattr(other, n)) for n, _ in _VECTORS)

    __hash__ = None  # type: ignore[assignment]  # mutable arrays


@dataclass
class Keyframe:
    """A kept pose: time (s), label, bone poses by name, extra JSON fields (line, peak_force…)."""

    time: float
    label: str
    bones: dict[str, BonePose]
    extra: dict[str, Any] = field(default_factory=dict)


class KeyframeSet:
    """Keys sorted by time; adding a key at an existing time (within 1 ns) replaces it."""

    def __init__(self, keys: Iterable[Keyframe] = ()) -> None:
        self._keys: list[Keyframe] = []
        for key in keys:
            self.add(key)

    def add(self, key: Keyframe) -> None:
        """Insert ``key`` in time order, replacing the nearest key less than 1 ns away."""
        if not math.isfinite(key.time):
            raise ValueError(f"keyframe time must be finite, got {shown(key.time)}")
        i = bisect.bisect_left([k.time for k in self._keys], key.time)
        near = [j for j in (i - 1, i) if 0 <= j < len(self._keys)]
        j = min(near, key=lambda j: abs(self._keys[j].time - key.time), default=None)
        if j is not None and abs(self._keys[j].time - key.time) < SAME_TIME:
            self._keys[j] = key
        else:
            self._keys.insert(i, key)

    def pop(self) -> Keyframe:
        """Remove and return the latest key (IndexError when there is none)."""
        return self._keys.pop()

    def __iter__(self) -> Iterator[Keyframe]:
        return iter(list(self._keys))

    def __len__(self) -> int:
        return len(self._keys)


def _key_json(index: int, key: Keyframe, bone_names: list[str] | None) -> dict:
    """The JSON object of one key, checked: finite values, unit quaternions, reserved names."""
    where = f"key {index} (t = {key.time!r} s)"
    if not math.isfinite(key.time):
        raise ValueError(f"{where}: time is not finite")
    if abs(key.time) > LARGEST:  # what read_keyframes would refuse
        raise ValueError(f"{where}: time is beyond ±{LARGEST:g} s")
    clash = [name for name in _RESERVED if name in key.extra]
    if clash:
        raise ValueError(f"{where}: extra field {clash[0]!r} is reserved")
    if bone_names is not None and set(key.bones) != set(bone_names):
        raise ValueError(f"{where}: bones {sorted(key.bones)} differ from key 0's {bone_names}")
    bones = {}
    for name, pose in key.bones.items():
        for field_name, n in _VECTORS:
            value = getattr(pose, field_name)
            if not np.all(np.isfinite(value)):
                raise ValueError(f"{where}: bone {name!r} {field_name} is not finite")
            if not np.all(np.abs(value) <= LARGEST):
                raise ValueError(f"{where}: bone {name!r} {field_name} is beyond ±{LARGEST:g}")
            if n == 4 and abs(np.linalg.norm(value) - 1.0) > UNIT_TOLERANCE:
                raise ValueError(f"{where}: bone {name!r} {field_name} is not a unit quaternion")
        bones[name] = {f: getattr(pose, f).tolist() for f, _ in _VECTORS}
    return {"time": float(key.time), "label": key.label, **key.extra, "bones": bones}


def write_keyframes(path: Path, rig_name: str, keys: Iterable[Keyframe]) -> None:
    """Write keyframes.json atomically; keys must be strictly increasing in time.

    Non-finite values, numbers beyond ±1e9 (yamldoc.LARGEST, which the reader refuses),
    non-unit quaternions, differing bone sets and extra fields named like the reserved
    ones raise ``ValueError`` before anything is written.
    """
    out: list[dict] = []
    bone_names: list[str] | None = None
    previous = -math.inf
    for i, key in enumerate(keys):
        out.append(_key_json(i, key, bone_names))
        if not key.time > previous:
            raise ValueError(f"key {i} (t = {key.time!r} s) is not after the previous key")
        bone_names = sorted(key.bones) if bone_names is None else bone_names
        previous = key.time
    write_json_atomic(path, {"rig": rig_name, "keys": out})


# ---- reading: every problem is one line "<file>:<json.path>: expected X, got Y" ----


def _describe(value: Any) -> str:
    """A short description of a JSON value for error messages."""
    if isinstance(value, dict):
        return "an object"
    if isinstance(value, list):
        return f"an array of {len(value)} item{'s' if len(value) != 1 else ''}"
    text = json.dumps(value)  # null, true, 1.5, NaN, "text"
    return text if len(text) <= 40 else text[:36] + '..."'


def _fail(path: Path, where: str, expected: str, found: str) -> NoReturn:
    location = f"{path}:{where}" if where else f"{path}"
    raise KeyframesError(f"{location}: expected {expected}, got {found}")


def _member(where: str, name: str) -> str:
    """JSON path of object member ``name``: ``a.b`` or ``a["odd name"]``."""
    if name.isidentifier():
        return f"{where}.{name}" if where else name
    return f"{where}[{json.dumps(name)}]"


def _get(path: Path, obj: dict, where: str, name: str, expected: str, kind: type) -> Any:
    """Member ``name`` of ``obj``, which must exist and be of JSON type ``kind``."""
    if name not in obj:
        _fail(path, _member(where, name), expected, "no such field")
    value = obj[name]
    if not isinstance(value, kind) or isinstance(value, bool):
        _fail(path, _member(where, name), expected, _describe(value))
    return value


def _number(path: Path, value: Any, where: str) -> float:
    ok = isinstance(value, int | float) and not isinstance(value, bool)
    try:
        ok = ok and math.isfinite(value)
    except OverflowError:  # an integer literal too large for a float
        ok = False
    if not ok:
        _fail(path, where, "a finite number", _describe(value))
    if abs(value) > LARGEST:
        _fail(path, where, f"a number of magnitude at most {LARGEST:g}", _describe(value))
    return float(value)


def _vector(path: Path, obj: dict, where: str, name: str, n: int) -> np.ndarray:
    expected = f"an array of {n} numbers"
    value = _get(path, obj, where, name, expected, list)
    at = _member(where, name)
    if len(value) != n:
        _fail(path, at, expected, _describe(value))
    vector = np.array([_number(path, v, f"{at}[{i}]") for i, v in enumerate(value)])
    if n == 4 and abs(np.linalg.norm(vector) - 1.0) > UNIT_TOLERANCE:
        _fail(path, at, "a unit quaternion [w, x, y, z]", f"norm {np.linalg.norm(vector):.6g}")
    return vector


def _read_key(path: Path, item: Any, where: str) -> Keyframe:
    """One key object, validated field by field."""
    if not isinstance(item, dict):
        _fail(path, where, 'a key object with "time", "label" and "bones"', _describe(item))
    time_json = _get(path, item, where, "time", "a finite number", int | float)
    time = _number(path, time_json, _member(where, "time"))
    label = _get(path, item, where, "label", "a string", str)
    bones_json = _get(path, item, where, "bones", "an object of bone poses", dict)
    bones = {}
    for name, pose in bones_json.items():
        at = _member(_member(where, "bones"), name)
        if not isinstance(pose, dict):
            _fail(path, at, 'a bone pose with "head", "rotation" and "local"', _describe(pose))
        vectors = {f: _vector(path, pose, at, f, n) for f, n in _VECTORS}
        bones[name] = BonePose(**vectors)
    extra = {k: v for k, v in item.items() if k not in _RESERVED}
    return Keyframe(time=time, label=label, bones=bones, extra=extra)


def _load(path: Path) -> Any:
    """The parsed JSON document of ``path``."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except OSError as exc:
        raise KeyframesError(f"{path}: cannot read: {exc.strerror or exc}") from exc
    except UnicodeDecodeError as exc:
        raise KeyframesError(
            f"{path}: expected UTF-8 JSON, got byte {exc.start} undecodable"
        ) from exc
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise KeyframesError(
            f"{path}: expected JSON, got invalid text at line {exc.lineno} column {exc.colno}"
            f" ({exc.msg})"
        ) from exc
    except RecursionError as exc:
        raise KeyframesError(f"{path}: expected JSON, got nesting too deep to read") from exc


def _check_sequence(path: Path, i: int, key: Keyframe, first: Keyframe, last: Keyframe) -> None:
    """Key ``i`` must come after the previous key and hold the same bones as keys[0]."""
    if not key.time > last.time:
        expected = f"a time after {last.time!r} s (keys sorted by time)"
        _fail(path, f"keys[{i}].time", expected, repr(key.time))
    missing = [name for name in first.bones if name not in key.bones]
    unknown = [name for name in key.bones if name not in first.bones]
    if missing or unknown:
        found = f"no bone {missing[0]!r}" if missing else f"unknown bone {unknown[0]!r}"
        _fail(path, f"keys[{i}].bones", "the same bones as keys[0]", found)


def read_keyframes(path: Path) -> tuple[str, list[Keyframe]]:
    """Read and validate keyframes.json: (rig name, keys in time order).

    Any structural problem raises :class:`KeyframesError` naming the file, the
    JSON path, what was expected and what was found.
    """
    doc = _load(path)
    if not isinstance(doc, dict):
        _fail(path, "", 'a JSON object with "rig" and "keys"', _describe(doc))
    rig = _get(path, doc, "", "rig", "the rig name (a string)", str)
    items = _get(path, doc, "", "keys", "an array of keys", list)
    keys: list[Keyframe] = []
    for i, item in enumerate(items):
        key = _read_key(path, item, f"keys[{i}]")
        if keys:
            _check_sequence(path, i, key, keys[0], keys[-1])
        keys.append(key)
    return rig, keys
