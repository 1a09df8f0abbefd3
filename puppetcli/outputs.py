"""Atomic output files and the output-directory overwrite policy.

Every file puppetcli produces is written to a temporary name in the same
directory and renamed over the target (``os.replace`` is atomic on POSIX and
Windows when source and target share a filesystem), so a crash never leaves a
torn output and readers never see a half-written file.  Existing outputs are
only overwritten when the user passes ``--force``.
"""

from __future__ import annotations

import itertools
import os
from collections.abc import Iterator, Sequence
from contextlib import contextmanager, suppress
from pathlib import Path
from typing import Any

from puppetcli.errors import PuppetError
from puppetcli.jsontext import json_text

__all__ = [
    "OutputError",
    "atomic_path",
    "prepare_outdir",
    "write_json_atomic",
    "write_text_atomic",
]

# Distinguishes several temporaries for one target inside a single process.
_counter = itertools.count()
SHORT_NAME = 200  # characters of a target's name that leave room for the temporary's tag


class OutputError(PuppetError):
    """An output cannot be written (exists without --force, is not a directory, or the file
    system refuses it)."""


def _temp_path(path: Path) -> Path:
    """A hidden, unique temporary name next to ``path`` (same filesystem, so rename is atomic);
    for a name near the file system's limit, a short one (the target's own name must fit)."""
    tag = f"tmp-{os.getpid()}-{next(_counter)}"
    name = f".{path.name}.{tag}" if len(path.name) <= SHORT_NAME else f".puppetcli-{tag}"
    return path.with_name(name)


@contextmanager
def atomic_path(path: Path, *, keep_on_error: bool = False) -> Iterator[Path]:
    """Yield a temporary path to write; publish it as ``path`` when the block ends.

    On normal exit the temporary file replaces ``path``.  When the block raises,
    the temporary is published anyway if ``keep_on_error`` (used for traces:
    whatever was captured before a simulation error is kept) and removed
    otherwise.  If the block never created the temporary, ``path`` is untouched.
    The file system refusing the temporary or the target (a missing or unwritable
    folder, a name too long, a directory in the way) is an ``OutputError`` naming
    ``path``: one line for the user, not a traceback.
    """
    path = Path(path)
    tmp = _temp_path(path)
    try:
        yield tmp
    except BaseException as exc:
        _settle(tmp, path if keep_on_error else None)
        if isinstance(exc, OSError) and _names(exc, tmp, path):
            raise _cannot_write(path, exc) from exc
        raise
    try:
        os.replace(tmp, path)
    except OSError as exc:
        _settle(tmp, None)
        raise _cannot_write(path, exc) from exc


def _settle(tmp: Path, publish: Path | None) -> None:
    """After a failed block: publish ``tmp`` as ``publish`` when given and possible, else
    remove it; never raise (the block's own error is the one to report)."""
    with suppress(OSError):
        if publish is not None and tmp.exists():
            os.replace(tmp, publish)
            return
        tmp.unlink(missing_ok=True)


def _names(exc: OSError, *paths: Path) -> bool:
    """``exc`` is about one of ``paths``."""
    named = {os.fspath(f) for f in (exc.filename, exc.filename2) if f is not None}
    return bool(named & {os.fspath(p) for p in paths})


def _cannot_write(path: Path, exc: OSError) -> OutputError:
    return OutputError(f"{path}: cannot write: {exc.strerror or exc}")


def write_text_atomic(path: Path, text: str) -> None:
    """Write ``text`` (UTF-8, ``\\n`` line ends) to ``path`` atomically, synced to disk."""
    with atomic_path(path) as tmp, open(tmp, "w", encoding="utf-8", newline="\n") as f:
        f.write(text)
        f.flush()
        os.fsync(f.fileno())


def write_json_atomic(path: Path, obj: Any) -> None:
    """Write ``obj`` as JSON (see :func:`json_text`) to ``path`` atomically.

    The text is built before any file is touched, so a NaN leaves no trace on disk.
    """
    write_text_atomic(path, json_text(obj))


def refuse_overwrite(path: Path, force: bool) -> None:
    """Stop with a clear line unless ``path`` is free to write: absent, or ``force``."""
    if not force and (path.exists() or path.is_symlink()):
        raise OutputError(f"{path} exists: pass --force to overwrite")


def make_parent(path: Path) -> None:
    """Create the folder ``path`` goes in (and its parents)."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"{path.parent}: cannot create directory: {exc.strerror}") from exc


def prepare_outdir(outdir: Path, names: Sequence[str], force: bool) -> None:
    """Create ``outdir`` and refuse to overwrite any of ``names`` in it unless ``force``."""
    outdir = Path(outdir)
    if outdir.exists() and not outdir.is_dir():
        raise OutputError(f"{outdir} exists and is not a directory")
    try:
        outdir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"{outdir}: cannot create directory: {exc.strerror}") from exc
    for name in names:
        refuse_overwrite(outdir / name, force)
