"""A recorded session replayed into a temporary trace, for commands that read traces
(``render``, ``fit``)."""

from __future__ import annotations

import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import TypeVar

import click

from puppetcli.mcap.replay import load_replay, replay_traced
from puppetcli.run.budget import check_run
from puppetcli.run.runner import script_model
from solver.model import build_model
from solver.spec import RigSpec

__all__ = ["session_trace"]

T = TypeVar("T")


def session_trace(path: Path, spec: RigSpec, yes: bool, read: Callable[[Path], T]) -> T:
    """``read(trace)`` of the trace of every step of the session at ``path`` replayed on
    ``spec`` (the run's budget checked first; a replay warning on stderr)."""
    replay = load_replay(path, spec)
    if replay.warning:
        click.echo(f"warning: {replay.warning}", err=True)
    model = script_model(build_model(spec), replay.script)
    check_run(path, replay.script, model.options.h, len(spec.bones), yes, trace_every=1)
    with tempfile.TemporaryDirectory() as tmp:
        result = replay_traced(replay, model, Path(tmp) / "trace.mcap")
        if result.error is not None:
            raise result.error
        return read(Path(tmp) / "trace.mcap")
