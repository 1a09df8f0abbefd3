"""Compact JSON of messages whose shape is fixed and whose numbers change every step.

A trace writes the same messages hundreds of times a second of simulated time, and
``json.dumps`` spends most of its time re-encoding what never changes (keys, frame
names, colours).  A ``MessageTemplate`` encodes a message once with ``Slot`` leaves
where the numbers go, and then writes each message by putting the numbers in:
``str.format`` writes a float as ``repr`` does, as ``json.dumps`` does, so a filled
template is byte for byte the message ``json_bytes`` would write
(tests/puppetcli/mcap/test_template.py).
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

__all__ = ["MessageTemplate", "Slot", "slots"]

_MARK = "\x00slot:"
_MARK_TEXT = re.compile(r'"\\u0000slot:([^"]+):(\d+)"')


@dataclass(frozen=True)
class Slot:
    """The place of element ``index`` of the numbers called ``group`` in a message."""

    group: str
    index: int = 0


def slots(group: str, shape: tuple[int, ...]) -> np.ndarray:
    """An array of ``shape`` whose elements are the Slots of ``group`` in C order: a stand-in
    for the group's numbers that a message builder can reshape and ``tolist``."""
    flat = np.empty(int(np.prod(shape)), dtype=object)
    flat[:] = [Slot(group, i) for i in range(flat.size)]
    return flat.reshape(shape)


class MessageTemplate:
    """``shape``: a message with Slot leaves; ``groups``: (name, size) of each group of
    numbers, in the order ``fill`` takes them."""

    def __init__(self, shape: dict, groups: Sequence[tuple[str, int]]) -> None:
        offsets, start = {}, 0
        for name, size in groups:
            offsets[name] = start
            start += size
        self.size = start
        text = json.dumps(shape, separators=(",", ":"), default=_mark)
        text = text.replace("{", "{{").replace("}", "}}")
        used: set[int] = set()

        def place(match: re.Match) -> str:
            index = offsets[match[1]] + int(match[2])
            used.add(index)
            return f"{{{index}}}"

        self._format = _MARK_TEXT.sub(place, text)
        if used != set(range(self.size)):
            raise ValueError(f"template uses {len(used)} of its {self.size} numbers")

    def fill(self, numbers: list) -> bytes:
        """The message with ``numbers`` (ints and floats, groups in order) as UTF-8; NaN and
        infinities raise ValueError (strict JSON parsers reject them)."""
        if len(numbers) != self.size:
            raise ValueError(f"expected {self.size} numbers, got {len(numbers)}")
        if not all(map(math.isfinite, numbers)):
            raise ValueError("Out of range float values are not JSON compliant")  # as json's
        return self._format.format(*numbers).encode()


def _mark(obj: object) -> str:
    """json's fallback: a Slot becomes a string the template then replaces."""
    if not isinstance(obj, Slot):
        raise TypeError(f"cannot write {type(obj).__name__} in a message template")
    return f"{_MARK}{obj.group}:{obj.index}"
