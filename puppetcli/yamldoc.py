"""Typed reading of YAML documents, with file, line and YAML path in every error.

A document is composed (not constructed) with ``yaml.compose`` so that every
node keeps its ``start_mark``; values are then read through ``Node`` methods
that check type and range and raise the caller's error class with one line::

    rigs/doll.yaml:42: bones[3].joint.kf: expected a non-negative finite number, got -1

The same reader serves rigs, scripts and any later YAML input: the caller picks
the error class (``RigError``, ``ScriptError`` …) when it loads the document.

Numbers: PyYAML follows YAML 1.1, whose float pattern needs a dot, so ``1e3``
arrives as a string; numeric strings are therefore accepted, while ``.nan``,
``.inf`` and booleans never count as numbers.  Names must be real strings, so
``on``/``yes``/``no`` (YAML 1.1 booleans) are rejected where a name is expected.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Callable, Collection, Iterator, Sequence
from pathlib import Path
from typing import NoReturn, TypeVar

import numpy as np
import yaml
from yaml.constructor import SafeConstructor

from puppetcli.errors import PuppetError, clip

__all__ = ["Fields", "Node", "did_you_mean", "load_file", "load_text"]

ErrorType = type[PuppetError]
T = TypeVar("T")
FAST_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)  # libyaml, when pyyaml has it
# Every number read is at most LARGEST in magnitude, and a positive one at least SMALLEST:
# products of a few such values (inertia = m·r², its inverse, their squares in the solver)
# stay far inside float64, so no overflow reaches the arithmetic of a run.
LARGEST = 1e9
SMALLEST = 1e-9
FAST_DEPTH = 5000  # libyaml's composer recurses in C: 10,000 levels pass, 100,000 crash


def did_you_mean(word: str, known: Collection[str]) -> str:
    """`` (did you mean 'x'?)`` for the closest known name, or an empty string."""
    close = difflib.get_close_matches(word, sorted(known), n=1)
    return f" (did you mean '{close[0]}'?)" if close else ""


def load_text(text: str, source: str, error: ErrorType) -> Node:
    """Compose one YAML document; its top level must be a mapping (checked by the caller).

    libyaml composes (~14× faster than pure Python, the same nodes) what cannot nest
    deeper than its recursion survives (``_shallow``); a document it refuses is composed
    again in Python for pyyaml's own error message."""
    if _shallow(text):
        try:
            return _root(yaml.compose(text, Loader=FAST_LOADER), source, error)
        except yaml.YAMLError:
            pass
    try:
        root = yaml.compose(text, Loader=yaml.SafeLoader)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        line = f":{mark.line + 1}" if mark is not None else ""
        problem = str(exc.problem or exc.context or "unreadable")
        if problem.startswith("but ") and exc.context:  # "… a single document, but found …"
            problem = f"{exc.context}, {problem}"
        raise error(f"{source}{line}: YAML syntax error: {' '.join(problem.split())}") from None
    except yaml.reader.ReaderError as exc:
        line = text.count("\n", 0, max(exc.position, 0)) + 1
        raise error(f"{source}:{line}: YAML syntax error: {exc.reason}") from None
    except yaml.YAMLError as exc:
        raise error(f"{source}: YAML error: {' '.join(str(exc).split())}") from None
    except RecursionError:
        deep = "YAML nests too deeply (rigs and scripts need a few levels)"
        raise error(f"{source}: {deep}") from None
    return _root(root, source, error)


def _shallow(text: str) -> bool:
    """``text`` nests fewer than FAST_DEPTH levels: each level takes an indentation column
    or one of ``[{-?``, so their count bounds the depth."""
    marks = sum(text.count(c) for c in "[{-?")
    indent = max((len(line) - len(line.lstrip(" ")) for line in text.splitlines()), default=0)
    return marks + indent < FAST_DEPTH


def _root(root: yaml.Node | None, source: str, error: ErrorType) -> Node:
    if root is None:
        raise error(f"{source}:1: expected a YAML mapping, got an empty document")
    return Node(root, source, "", error)


def load_file(path: Path, error: ErrorType) -> Node:
    """Read and compose a YAML file; unreadable files raise ``error`` too."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except OSError as exc:
        raise error(f"{path}: cannot read: {exc.strerror or exc}") from None
    except UnicodeDecodeError as exc:
        raise error(f"{path}: expected UTF-8 text, got byte {exc.object[exc.start]:#04x}") from None
    return load_text(text, str(path), error)


def _range_text(minimum: float | None, maximum: float | None, exclusive: bool) -> str:
    """Words for the accepted range of a number."""
    if minimum is None and maximum is None:
        return "a finite number"
    if maximum is None:
        if minimum == 0:
            return "a positive finite number" if exclusive else "a non-negative finite number"
        return f"a finite number {'>' if exclusive else '>='} {minimum:g}"
    if minimum is None:
        return f"a finite number <= {maximum:g}"
    return f"a number in {'(' if exclusive else '['}{minimum:g}, {maximum:g}]"


class Node:
    """One YAML node with where it came from: file, YAML path and 1-based line."""

    __slots__ = ("error", "node", "path", "source")

    def __init__(self, node: yaml.Node, source: str, path: str, error: ErrorType) -> None:
        self.node = node
        self.source = source
        self.path = path
        self.error = error

    @property
    def line(self) -> int:
        """1-based line where the node starts."""
        return self.node.start_mark.line + 1

    def child(self, node: yaml.Node, step: str | int) -> Node:
        """A sub-node at mapping key ``step`` (str) or list index ``step`` (int)."""
        if isinstance(step, int):
            path = f"{self.path}[{step}]"
        else:
            step = clip(step)
            path = f"{self.path}.{step}" if self.path else step
        return Node(node, self.source, path, self.error)

    def fail(self, expected: str, got: str | None = None, hint: str = "") -> NoReturn:
        """Raise the one-line error ``file:line: path: expected …, got …``."""
        found = self.describe() if got is None else got
        where = f"{self.source}:{self.line}: {self.path or 'document'}"
        raise self.error(f"{where}: expected {expected}, got {found}{hint}")

    def value(self) -> object:
        """The constructed Python value of a scalar; the raw text if its tag is unknown."""
        if not isinstance(self.node, yaml.ScalarNode):
            return None
        try:
            return SafeConstructor().construct_object(self.node)
        except (yaml.YAMLError, ValueError):
            return self.node.value

    def describe(self) -> str:
        """Short words for what the node holds, used after ``got``."""
        node = self.node
        if isinstance(node, yaml.SequenceNode):
            count = len(node.value)
            return "an empty list" if count == 0 else f"a list of {count} item{'s' * (count != 1)}"
        if isinstance(node, yaml.MappingNode):
            return "a mapping" if node.value else "an empty mapping"
        value = self.value()
        if value is None:
            return "null"
        if isinstance(value, bool):
            return f"boolean {str(value).lower()}"
        if isinstance(value, (int, float)) or self._number_or_none() is not None:
            return clip(node.value)  # numbers (and numeric strings such as 1e3) as written
        text = str(node.value)
        if not text:
            return "an empty string"
        return f"'{clip(text)}'"

    def is_null(self) -> bool:
        """True for an explicit YAML null (``~``, ``null`` or nothing)."""
        return isinstance(self.node, yaml.ScalarNode) and self.value() is None

    def mapping(
        self, allowed: Collection[str], required: Collection[str] = (), what: str = "a mapping"
    ) -> Fields:
        """Read a mapping whose keys are among ``allowed`` and include ``required``."""
        if not isinstance(self.node, yaml.MappingNode):
            self.fail(what)
        entries: dict[str, tuple[Node, Node]] = {}
        for key_node, value_node in self.node.value:
            key = self.child(key_node, str(key_node.value))
            name = key.value()
            if not isinstance(name, str) or name not in allowed:
                hint = did_you_mean(str(key_node.value), allowed)
                key.fail(f"one of the keys {', '.join(allowed)}", hint=hint)
            if name in entries:
                first = entries[name][0].line
                key.fail("each key once", got=f"'{name}' again (first at line {first})")
            entries[name] = (key, self.child(value_node, name))
        for name in required:
            if name not in entries:
                self.fail(f"a value for '{name}'", got=f"no '{name}' key")
        return Fields(self, entries)

    def items(self, what: str = "a list") -> list[Node]:
        """Read a list; returns its items as nodes with indexed paths."""
        if not isinstance(self.node, yaml.SequenceNode):
            self.fail(what)
        return [self.child(item, i) for i, item in enumerate(self.node.value)]

    def string(self, what: str = "a string") -> str:
        """Read a non-empty string; booleans and numbers are refused (quote them)."""
        value = self.value()
        if not isinstance(self.node, yaml.ScalarNode) or not isinstance(value, str) or not value:
            self.fail(what)
        return value

    def choice(self, options: Sequence[str], what: str | None = None) -> str:
        """Read a string that must be one of ``options`` (with a did-you-mean hint)."""
        expected = what or f"one of {', '.join(options)}"
        value = self.string(expected)
        if value not in options:
            self.fail(expected, hint=did_you_mean(value, options))
        return value

    def _number_or_none(self) -> float | None:
        """The node as a float (possibly non-finite), or None when it is not a number."""
        value = self.value()
        if not isinstance(self.node, yaml.ScalarNode) or isinstance(value, bool):
            return None
        try:
            return float(value) if isinstance(value, (int, float, str)) else None
        except ValueError:
            return None
        except OverflowError:
            return math.inf

    def number(
        self,
        minimum: float | None = None,
        maximum: float | None = None,
        exclusive: bool = False,
    ) -> float:
        """Read a finite number in [minimum, maximum] ((minimum, …] when ``exclusive``)."""
        expected = _range_text(minimum, maximum, exclusive)
        value = self._number_or_none()
        if value is None or not math.isfinite(value):
            self.fail(expected)
        too_low = minimum is not None and (value <= minimum if exclusive else value < minimum)
        if too_low or (maximum is not None and value > maximum):
            self.fail(expected)
        if abs(value) > LARGEST:
            self.fail(f"{expected} of magnitude at most {LARGEST:g}")
        if minimum == 0.0 and value < SMALLEST and (exclusive or value > 0.0):
            self.fail(f"{expected}: 0 or at least {SMALLEST:g}" if not exclusive
                      else f"{expected} of at least {SMALLEST:g}")  # fmt: skip
        return value

    def positive(self) -> float:
        """Read a finite number > 0."""
        return self.number(0.0, exclusive=True)

    def non_negative(self) -> float:
        """Read a finite number >= 0."""
        return self.number(0.0)

    def integer(self, minimum: int = 1) -> int:
        """Read an integer >= ``minimum``."""
        expected = "a positive integer" if minimum == 1 else f"an integer >= {minimum}"
        value = self.value()
        if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
            self.fail(expected)
        return value

    def boolean(self) -> bool:
        """Read true or false."""
        value = self.value()
        if not isinstance(value, bool):
            self.fail("true or false")
        return value

    def vector(
        self,
        n: int,
        minimum: float | None = None,
        maximum: float | None = None,
        exclusive: bool = False,
    ) -> np.ndarray:
        """Read a list of exactly ``n`` finite numbers (each within the given bounds)."""
        expected = f"a list of {n} numbers"
        if not isinstance(self.node, yaml.SequenceNode) or len(self.node.value) != n:
            self.fail(expected)
        items = self.items()
        return np.array([item.number(minimum, maximum, exclusive) for item in items])

    def scalar_or_vector(
        self,
        n: int = 3,
        minimum: float | None = None,
        maximum: float | None = None,
        exclusive: bool = False,
    ) -> np.ndarray:
        """Read one number (used for all ``n`` axes) or a list of ``n``; returns shape (n,)."""
        if isinstance(self.node, yaml.SequenceNode):
            return self.vector(n, minimum, maximum, exclusive)
        if self._number_or_none() is None:
            self.fail(f"a number or a list of {n} numbers")
        return np.full(n, self.number(minimum, maximum, exclusive))


class Fields:
    """The checked entries of a mapping node, by key."""

    __slots__ = ("_entries", "node")

    def __init__(self, node: Node, entries: dict[str, tuple[Node, Node]]) -> None:
        self.node = node
        self._entries = entries

    def __contains__(self, key: str) -> bool:
        return key in self._entries

    def __getitem__(self, key: str) -> Node:
        """The value node of a present key (required keys are always present)."""
        return self._entries[key][1]

    def __iter__(self) -> Iterator[str]:
        """Present keys in document order."""
        return iter(self._entries)

    def key_node(self, key: str) -> Node:
        """The node of the key itself (for errors about the key)."""
        return self._entries[key][0]

    def raw(self, key: str) -> Node | None:
        """The value node, or None when the key is absent (an explicit null is returned)."""
        entry = self._entries.get(key)
        return None if entry is None else entry[1]

    def get(self, key: str) -> Node | None:
        """The value node, or None when the key is absent or its value is null."""
        node = self.raw(key)
        return None if node is None or node.is_null() else node

    def read(self, key: str, reader: Callable[[Node], T], default: T) -> T:
        """``reader(value)``, or ``default`` when the key is absent or null."""
        node = self.get(key)
        return default if node is None else reader(node)
