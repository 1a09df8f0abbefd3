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
from contextlib import contextmanager
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


class OutputError(PuppetError):
    """An output cannot be written (exists without --force, or is not a directory)."""


def _temp_path(path: Path) -> Path:
    """A hidden, unique temporary name next to ``path`` (same filesystem, so rename is atomic)."""
    return path.with_name(f".{path.name}.tmp-{os.getpid()}-{next(_counter)}")


@contextmanager
def atomic_path(path: Path, *, keep_on_error: bool = False) -> Iterator[Path]:
    """Yield a temporary path to write; publish it as ``path`` when the block ends.

    On normal exit the temporary file replaces ``path``.  When the block raises,
    the temporary is published anyway if ``keep_on_error`` (used for traces:
    whatever was captured before a simulation error is kept) and removed
    otherwise.  If the block never created the temporary, ``path`` is untouched.
    """
    path = Path(path)
    tmp = _temp_path(path)
    try:
        yield tmp
    except BaseException:
        if keep_on_error and tmp.exists():
            os.replace(tmp, path)
        else:
            tmp.unlink(missing_ok=True)
        raise
    try:
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


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
