"""The one JSON encoder of puppetcli's outputs.

``json_text``: deterministic, readable files (keyframes.json, bench results): 2-space
indent, key order as given, lists of scalars on one line.  ``json_bytes``: the compact
UTF-8 of a message (MCAP traces and sessions, the live page's protocol).  Both write
floats with ``repr`` precision (an exact round trip), take numpy arrays and scalars as
the lists and numbers they hold, and refuse NaN and infinities with ``ValueError``
(strict JSON parsers, Foxglove's among them, reject them).
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np

__all__ = ["json_bytes", "json_text", "plain"]


def plain(obj: Any) -> Any:
    """Turn numpy arrays and scalars into the Python lists/numbers json understands."""
    if isinstance(obj, np.ndarray | np.generic):
        return obj.tolist()
    return obj


def _is_container(obj: Any) -> bool:
    return isinstance(obj, dict | list | tuple | np.ndarray)


def _encode(obj: Any, level: int) -> str:
    """Recursive pretty encoder: 2-space indent, lists of scalars kept on one line."""
    obj = plain(obj)
    pad, inner = "  " * level, "  " * (level + 1)
    if isinstance(obj, dict):
        if not obj:
            return "{}"
        for key in obj:
            if not isinstance(key, str):
                raise TypeError(f"JSON object keys must be strings, got {key!r}")
        items = [f"{inner}{json.dumps(k)}: {_encode(v, level + 1)}" for k, v in obj.items()]
        return "{\n" + ",\n".join(items) + "\n" + pad + "}"
    if isinstance(obj, list | tuple):
        if not any(_is_container(v) for v in obj):
            return "[" + ", ".join(_encode(v, level + 1) for v in obj) + "]"
        items = [inner + _encode(v, level + 1) for v in obj]
        return "[\n" + ",\n".join(items) + "\n" + pad + "]"
    # Scalars: json.dumps gives repr-exact floats and rejects NaN/Infinity.
    return json.dumps(obj, allow_nan=False)


def json_text(obj: Any) -> str:
    """Deterministic, human-readable JSON for ``obj`` (key order as given), newline-terminated.

    Floats are written with ``repr`` precision (exact round trip); NaN and
    infinities raise ``ValueError`` because strict JSON parsers reject them.
    """
    return _encode(obj, 0) + "\n"


def json_bytes(message: Any) -> bytes:
    """Compact JSON of ``message`` as UTF-8 (module docstring)."""
    return json.dumps(message, allow_nan=False, separators=(",", ":"), default=_default).encode()


def _default(obj: Any) -> Any:
    """json's fallback for what it cannot write: numpy values as plain ones, else an error."""
    value = plain(obj)
    if value is obj:
        raise TypeError(f"cannot write {type(obj).__name__} as JSON")
    return value
