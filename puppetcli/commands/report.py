"""What a command tells its user when it ends: the human summary on stdout, or, with
``--json``, one JSON document on stdout holding the same facts (the human lines are then
not printed).  A command that fails with ``--json`` still prints one document,
``{"ok": false, "error": "…", "exit_code": N}``, besides its one ``error:`` line on stderr."""

from __future__ import annotations

import contextlib
import dataclasses
import math
import sys
from collections.abc import Callable, Iterator
from typing import Any

import click

from puppetcli.jsontext import json_text, plain

__all__ = ["JSON_OPTION", "emit", "emit_failure", "progress_bar", "rows_json"]

_WANTED, _DONE = "puppetcli.json", "puppetcli.json_done"


def _remember(ctx: click.Context, param: click.Parameter, value: bool) -> bool:
    ctx.meta[_WANTED] = value
    return value


JSON_OPTION = click.option(
    "--json", "as_json", is_flag=True, callback=_remember, expose_value=True,
    help="Print one JSON document on stdout (the summary's facts) instead of the summary.",
)  # fmt: skip


def rows_json(rows: list) -> list[dict[str, Any]]:
    """Measured rows (dataclasses) as JSON objects, field by field."""
    return [dataclasses.asdict(row) for row in rows]


def _plain(value: Any) -> Any:
    """JSON-ready: numpy values as lists and numbers, NaN and infinities as null (strict
    JSON has neither), tuples as lists."""
    value = plain(value)
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def emit(summary: dict[str, Any], lines: list[str]) -> None:
    """Print ``lines`` (the human summary), or ``summary`` as JSON when --json was given."""
    ctx = click.get_current_context()
    if ctx.meta.get(_WANTED):
        click.echo(json_text(_plain({"ok": True, **summary})), nl=False)
        ctx.meta[_DONE] = True
    else:
        for line in lines:
            click.echo(line)


def emit_failure(ctx: click.Context, message: str, exit_code: int) -> None:
    """With --json, the failure as the command's one document, unless it printed one (a
    document with its own ``error`` field, as ``pose`` prints for a broken run)."""
    if ctx.meta.get(_WANTED) and not ctx.meta.get(_DONE):
        click.echo(json_text({"ok": False, "error": message, "exit_code": exit_code}), nl=False)


@contextlib.contextmanager
def progress_bar(label: str, length: int) -> Iterator[Callable[[int], None] | None]:
    """A progress callback taking a count: a bar on a terminal's stderr, None otherwise (long
    work stays quiet in pipes and logs)."""
    if not sys.stderr.isatty():
        yield None
        return
    with click.progressbar(length=max(1, length), label=label, file=sys.stderr) as bar:
        yield bar.update
