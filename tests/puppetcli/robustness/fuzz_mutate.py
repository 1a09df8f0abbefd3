"""Mutants of the files puppetcli reads: a parsed tree with one node changed, or the raw bytes
with one edit.  Every mutator takes a ``numpy.random.Generator`` and is deterministic in it."""

from __future__ import annotations

import copy
import math
import re
from typing import Any

import numpy as np

# Values a hand-edited or corrupted file may hold where a number, a name or a list belongs.
EXTREMES: list[Any] = [
    0, -1, 1, 0.0, -0.0, 1e-300, -1e-300, 1e-9, 1e9, 1e300, -1e300, 1e308 * 10, -1e308 * 10,
    math.nan, 2**63, -(2**63), 10**40, True, False, None, "", "x", "1e999", "nan",
    "line one\nline two\n\tthree", "\x00\x01\x02\x7fbinary\xff", "A" * 5000,
    "QUJDREVGR0hJSktMTU5PUFFSU1RVVldYWVo=" * 40, [], {}, [0], [1, 2], [1, 2, 3, 4, 5],
    [math.nan, 0, 0], [1e300, 1e300, 1e300], [[1]], {"a": 1}, list(range(300)),
]  # fmt: skip

# Text edits of a number token: the value a reader meets after the file's own syntax.
NUMBER_TEXTS = [
    "0", "-0", "-1", "1e308", "1e309", "-1e309", "nan", "NaN", "inf", "-inf", ".nan", ".inf",
    "1e-320", "99999999999999999999", "4294967296", "0x10", "1_000", "+", "-", "1e", "..",
    "2147483648", "9" * 400,
]  # fmt: skip

NUMBER = re.compile(rb"-?\d+(?:\.\d*)?(?:[eE][-+]?\d+)?")


def paths(tree: Any, prefix: tuple = ()) -> list[tuple]:
    """Every node's path (keys and indices) in a tree of dicts and lists, the root included."""
    out = [prefix]
    if isinstance(tree, dict):
        for key, value in tree.items():
            out += paths(value, (*prefix, key))
    elif isinstance(tree, list):
        for index, value in enumerate(tree):
            out += paths(value, (*prefix, index))
    return out


def _node(tree: Any, path: tuple) -> Any:
    for part in path:
        tree = tree[part]
    return tree


DEEP = re.compile(r"['\"]?@deep(\d+)@['\"]?")


def deep(levels: int) -> str:
    """A marker for a list nested ``levels`` deep, which :func:`expand_deep` writes out as
    ``[[[...]]]`` once the tree is text (the dumpers cannot recurse that deep)."""
    return f"@deep{levels}@"


def expand_deep(text: str) -> str:
    """``text`` with every :func:`deep` marker written out as nested brackets."""
    return DEEP.sub(lambda m: "[" * int(m[1]) + "]" * int(m[1]), text)


def mutate_tree(tree: Any, rng: np.random.Generator) -> Any:
    """A copy of ``tree`` with one node replaced, removed, duplicated or nested deeply."""
    tree = copy.deepcopy(tree)
    path = paths(tree)[int(rng.integers(len(paths(tree))))]
    if not path:
        return EXTREMES[int(rng.integers(len(EXTREMES)))]
    parent, last = _node(tree, path[:-1]), path[-1]
    op = int(rng.integers(8))
    if op <= 3:
        parent[last] = copy.deepcopy(EXTREMES[int(rng.integers(len(EXTREMES)))])
    elif op == 4:
        del parent[last]
    elif op == 5 and isinstance(parent, list):
        parent[last:last] = [copy.deepcopy(parent[last]) for _ in range(int(rng.integers(2, 400)))]
    elif op == 5:
        parent[f"{last}_unknown"] = parent[last]
    elif op == 6:
        parent[last] = deep(int(rng.integers(50, 3000)))
    else:
        value = parent[last]
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            parent[last] = value * float(rng.choice([-1.0, 1e-6, 1e6, 1e12, 1.01]))
        else:
            parent[last] = [value] if not isinstance(value, list) else {"k": value}
    return tree


def mutate_bytes(data: bytes, rng: np.random.Generator) -> bytes:
    """``data`` with one edit: a number token rewritten, a span cut, doubled or overwritten
    with junk, or the file truncated."""
    op = int(rng.integers(6))
    numbers = list(NUMBER.finditer(data))
    if op <= 1 and numbers:
        m = numbers[int(rng.integers(len(numbers)))]
        new = NUMBER_TEXTS[int(rng.integers(len(NUMBER_TEXTS)))].encode()
        return data[: m.start()] + new + data[m.end() :]
    if not data:
        return bytes(rng.integers(0, 256, 64, dtype=np.uint8))
    start = int(rng.integers(len(data)))
    length = int(rng.integers(1, 64))
    if op == 2:
        return data[:start]
    if op == 3:
        return data[:start] + data[start + length :]
    if op == 4:
        return data[:start] + data[start : start + length] * int(rng.integers(2, 50)) + data[start:]
    junk = bytes(rng.integers(0, 256, length, dtype=np.uint8))
    return data[:start] + junk + data[start + length :]
