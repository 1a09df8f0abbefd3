"""Read BVH files into ``puppetcli.bvh.model.Bvh``, one clear error line per problem.

Accepted: LF, CRLF or CR line ends; tabs or spaces; keywords in any case; a
``{`` on its own line or at the end of the ROOT/JOINT/End Site line; any
channel order per joint, any subset of the six channels (each at most once);
position channels on any joint (they replace its OFFSET, see ``puppetcli.bvh.model``);
non-zero root offsets; zero-length bones; joint names with spaces or ``:``
(the rest of the line is the name).

Rejected, each as ``<file>:<line>: expected …, got …`` (``BvhError``): a
missing ``HIERARCHY``, ``{`` or ``}``; a second ROOT; a malformed OFFSET; an
unknown or repeated channel name; a channel count that differs from the names
listed; a frame line with the wrong number of values; non-numeric or
non-finite values; fewer frame lines than ``Frames:`` says, or more.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import NoReturn

import numpy as np

from puppetcli.bvh.model import CHANNEL_NAMES, Bvh, BvhError, BvhJoint
from puppetcli.errors import shown
from puppetcli.yamldoc import LARGEST, did_you_mean

__all__ = ["bvh_from_text", "read_bvh"]

_CHANNELS_BY_LOWER = {c.lower(): c for c in CHANNEL_NAMES}


def read_bvh(path: Path) -> Bvh:
    """Read and check a BVH file; raises ``BvhError``."""
    try:
        data = Path(path).read_bytes()
    except OSError as exc:
        raise BvhError(f"{path}: cannot read: {exc.strerror or exc}") from exc
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        raise BvhError(f"{path}:{line}: expected UTF-8 text, got an undecodable byte") from None
    return bvh_from_text(text, str(path))


def bvh_from_text(text: str, source: str = "<bvh>") -> Bvh:
    """Parse BVH ``text``; ``source`` names it in error messages."""
    lines = _Lines(text, source)
    tokens = lines.next("'HIERARCHY'")
    if tokens[0].upper() != "HIERARCHY":
        lines.fail("'HIERARCHY' as the first word of the file", shown(tokens[0]))
    tokens = lines.next("'ROOT'")
    if tokens[0].upper() != "ROOT":
        lines.fail("'ROOT'", shown(tokens[0]))
    joints: list[BvhJoint] = []
    _read_joint(lines, tokens, -1, joints)
    tokens = lines.next("'MOTION'")
    if tokens[0].upper() == "ROOT":
        lines.fail("'MOTION' (one ROOT per file)", "a second 'ROOT'")
    if tokens[0].upper() != "MOTION":
        lines.fail("'MOTION'", shown(tokens[0]))
    nframes, frames_line = _read_frame_count(lines)
    frame_time = _read_frame_time(lines)
    nchannels = sum(len(j.channels) for j in joints)
    frames = _read_frames(lines, nframes, frames_line, nchannels)
    return Bvh(tuple(joints), frames, frame_time, source)


class _Lines:
    """The file's lines, split into whitespace-separated tokens, with a cursor."""

    def __init__(self, text: str, source: str) -> None:
        text = text.replace("\r\n", "\n").replace("\r", "\n")
        self.lines = text.split("\n")
        self.source = source
        self.index = 0  # next line to read
        self.line = 0  # 1-based number of the line last read

    def next(self, expected: str) -> list[str]:
        """Tokens of the next non-blank line; end of file is an error naming ``expected``."""
        tokens = self.peek()
        if tokens is None:
            self.line = len(self.lines)
            self.fail(expected, "end of file")
        self.line = self.index + 1
        self.index += 1
        return tokens

    def peek(self) -> list[str] | None:
        """Tokens of the next non-blank line without consuming it (None at end of file)."""
        while self.index < len(self.lines) and not self.lines[self.index].split():
            self.index += 1
        return self.lines[self.index].split() if self.index < len(self.lines) else None

    def fail(self, expected: str, got: str, line: int | None = None) -> NoReturn:
        raise BvhError(f"{self.source}:{line or self.line}: expected {expected}, got {got}")


def _header(lines: _Lines, tokens: list[str], what: str) -> tuple[str, bool]:
    """(name, brace given on the same line) of a ``ROOT name`` / ``JOINT name`` line."""
    opened = len(tokens) > 1 and tokens[-1] == "{"
    words = tokens[1:-1] if opened else tokens[1:]
    if not words:
        lines.fail(f"a joint name after '{what}'", "nothing")
    return " ".join(words), opened


def _open_brace(lines: _Lines, opened: bool, what: str) -> None:
    if not opened:
        tokens = lines.next(f"'{{' opening {what}")
        if tokens != ["{"]:
            lines.fail(f"'{{' opening {what}", shown(" ".join(tokens)))


MAX_DEPTH = 512  # nested joints (a rig has at most 512 bones); real skeletons nest a few dozen


@dataclass
class _Open:
    """A ROOT or JOINT block being read: its header, offset and channels, its End Sites."""

    index: int
    name: str
    parent: int
    offset: np.ndarray
    channels: tuple[str, ...]
    start: int
    what: str
    ends: list[np.ndarray] = field(default_factory=list)


def _read_joint(lines: _Lines, tokens: list[str], parent: int, joints: list[BvhJoint]) -> None:
    """A ROOT block (its header already read) and its subtree, appended in file order; nested
    blocks are read with a stack, so depth costs no recursion (it is bounded by MAX_DEPTH)."""
    stack = [_open_joint(lines, tokens, parent, joints)]
    while stack:
        block = stack[-1]
        closing = f"'JOINT', 'End Site' or '}}' closing {block.what} (line {block.start})"
        tokens = lines.next(closing)
        word = tokens[0].upper()
        if word == "JOINT":
            if len(stack) >= MAX_DEPTH:
                lines.fail(f"joints nested at most {MAX_DEPTH} deep", f"a deeper {block.what}")
            stack.append(_open_joint(lines, tokens, block.index, joints))
        elif word == "END" and len(tokens) > 1 and tokens[1].upper() == "SITE":
            block.ends.append(_read_end_site(lines, tokens, block.what))
        elif tokens == ["}"]:
            stack.pop()
            joints[block.index] = BvhJoint(
                block.name, block.parent, block.offset, block.channels, tuple(block.ends),
                block.start,
            )  # fmt: skip
        else:
            lines.fail(closing, shown(" ".join(tokens)))


def _open_joint(lines: _Lines, tokens: list[str], parent: int, joints: list[BvhJoint]) -> _Open:
    """Read a block's header, brace, OFFSET and CHANNELS; append its joint (ends to come)."""
    keyword = tokens[0].upper()
    name, opened = _header(lines, tokens, keyword)
    start = lines.line
    what = f"{keyword} '{name}'"
    _open_brace(lines, opened, what)
    offset = _read_offset(lines, what)
    channels = _read_channels(lines, what)
    joints.append(BvhJoint(name, parent, offset, channels, (), start))
    return _Open(len(joints) - 1, name, parent, offset, channels, start, what)


def _read_end_site(lines: _Lines, tokens: list[str], owner: str) -> np.ndarray:
    what = f"the End Site of {owner}"
    _open_brace(lines, len(tokens) > 2 and tokens[-1] == "{", what)
    offset = _read_offset(lines, what)
    tokens = lines.next(f"'}}' closing {what}")
    if tokens != ["}"]:
        lines.fail(f"'}}' closing {what}", shown(" ".join(tokens)))
    return offset


def _read_offset(lines: _Lines, what: str) -> np.ndarray:
    tokens = lines.next(f"'OFFSET x y z' of {what}")
    if tokens[0].upper() != "OFFSET":
        lines.fail(f"'OFFSET x y z' of {what}", shown(tokens[0]))
    if len(tokens) != 4:
        lines.fail(f"3 numbers after OFFSET of {what}", f"{len(tokens) - 1}")
    return np.array([_number(lines, t) for t in tokens[1:]])


def _read_channels(lines: _Lines, what: str) -> tuple[str, ...]:
    tokens = lines.next(f"'CHANNELS n ...' of {what}")
    if tokens[0].upper() != "CHANNELS":
        lines.fail(f"'CHANNELS n ...' of {what}", shown(tokens[0]))
    if len(tokens) < 2 or not tokens[1].isdigit():
        lines.fail(
            "a channel count after CHANNELS", shown(tokens[1]) if len(tokens) > 1 else "none"
        )
    count, names = int(tokens[1]), tokens[2:]
    if count > len(CHANNEL_NAMES):
        lines.fail(f"at most {len(CHANNEL_NAMES)} channels", shown(tokens[1]))
    if count != len(names):
        lines.fail(f"{count} channel names after 'CHANNELS {count}'", f"{len(names)}")
    channels: list[str] = []
    for name in names:
        channel = _CHANNELS_BY_LOWER.get(name.lower())
        if channel is None:
            hint = did_you_mean(name, CHANNEL_NAMES)
            lines.fail(f"a channel name (Xposition … Zrotation){hint}", shown(name))
        if channel in channels:
            lines.fail(f"each channel once in {what}", f"{channel} twice")
        channels.append(channel)
    return tuple(channels)


def _number(lines: _Lines, token: str) -> float:
    try:
        value = float(token)
    except ValueError:
        lines.fail("a number", shown(token))
    if not math.isfinite(value):
        lines.fail("a finite number", shown(token))
    if abs(value) > LARGEST:
        lines.fail(f"a number of magnitude at most {LARGEST:g}", shown(token))
    return value


def _read_frame_count(lines: _Lines) -> tuple[int, int]:
    """(N of ``Frames: N``, its line)."""
    tokens = lines.next("'Frames: N'")
    if tokens[0].lower() != "frames:" or len(tokens) != 2 or not tokens[1].isdigit():
        lines.fail("'Frames: N' (a whole number of frames)", shown(" ".join(tokens)))
    return int(tokens[1]), lines.line


def _read_frame_time(lines: _Lines) -> float:
    tokens = lines.next("'Frame Time: seconds'")
    if [t.lower() for t in tokens[:2]] != ["frame", "time:"] or len(tokens) != 3:
        lines.fail("'Frame Time: seconds'", shown(" ".join(tokens)))
    value = _number(lines, tokens[2])
    if value <= 0.0:
        lines.fail("a positive frame time (seconds per frame)", shown(tokens[2]))
    return value


def _read_frames(lines: _Lines, nframes: int, frames_line: int, nchannels: int) -> np.ndarray:
    """``nframes`` lines of ``nchannels`` finite numbers each, then the end of the file."""
    left = len(lines.lines) - lines.index  # frames are read by what is there, not declared
    if nframes > left:
        expected = f"as many frame lines as 'Frames:' says ({shown(str(nframes))})"
        lines.fail(expected, f"at most {left}", line=frames_line)
    frames = np.zeros((nframes, nchannels))
    for f in range(nframes):
        tokens = lines.peek()
        if tokens is None:
            expected = f"{nframes} frame lines after 'Frame Time:' (Frames: {nframes})"
            lines.fail(expected, f"{f}", line=frames_line)
        lines.next("")
        if len(tokens) != nchannels:
            lines.fail(f"{nchannels} values in frame {f} (one per channel)", f"{len(tokens)}")
        try:
            frames[f] = np.array(tokens, dtype=float)
        except ValueError:
            frames[f] = [_number(lines, t) for t in tokens]
        if not np.all(np.abs(frames[f]) <= LARGEST):  # NaN fails too
            bad = next(t for t, v in zip(tokens, frames[f], strict=True) if not abs(v) <= LARGEST)
            _number(lines, bad)
    if lines.peek() is not None:
        lines.next("")
        lines.fail(f"the end of the file after {nframes} frames (Frames: {nframes})", "more lines")
    return frames
