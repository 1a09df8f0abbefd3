"""How long a run will take, estimated before it starts, and the refusal of a run that would
take far longer than a user is likely to have meant (a tiny ``h``, a duration in hours, a
session whose clock jumps): such a run stops at once with one line saying what it would cost,
and ``--yes`` runs it anyway.

The costs are measured figures of this machine class (2026-12-04, compiled step): a step of
the 19-bone doll takes 32 µs, of the 100-link chains of ``stress`` 0.6–2.7 ms (contacts and
rows grow with the bones, the dense solves faster), so a step is estimated at
1.7 µs·n + 0.12 µs·n² for n bones (75 µs and 1.4 ms); without a trace the doll runs
31,000 steps/s, 1,760 steps/s writing trace.mcap, 2,500 device ticks/s
recorded into a session, video frames in 27 ms at 64×64 and 45 ms at 480×480.  An estimate
within a factor of a few is enough to tell seconds from hours.

The limit is 10 minutes; ``PUPPETCLI_RUN_LIMIT`` (seconds) sets another.  What the estimate
cannot see (stiff joints take up to 64 substeps a step) the run's ``BudgetWatch`` does: a run
whose measured pace projects more than twice the limit stops, keeping what it captured.
"""

from __future__ import annotations

import math
import os
import time

from puppetcli.errors import OverBudget, PuppetError, shown

__all__ = [
    "LIMIT", "BudgetWatch", "check_budget", "check_run", "run_length", "simulation_cost",
    "video_cost",
]  # fmt: skip

LIMIT = 600.0  # s of estimated wall time a command runs without --yes (default)
WATCH_AFTER = 5.0  # s of a run before its pace is trusted
SECONDS_PER_BONE_STEP = 1.7e-6  # compiled step, per bone (module docstring)
SECONDS_PER_BONE_PAIR_STEP = 1.2e-7  # and per bone squared
SECONDS_PER_TRACED_STEP = 5.7e-4  # one step written to trace.mcap (1 / 1,760 steps/s)
SECONDS_PER_TICK = 4e-4  # one 1 kHz device tick written to a session (1 / 2,500 ticks/s)
SECONDS_PER_VIDEO_FRAME = 0.025  # one video frame drawn and encoded, and per pixel on top:
SECONDS_PER_VIDEO_PIXEL = 0.02 / 480**2


def run_length(plan) -> float:
    """Simulated seconds of a script or a session's script: its duration or its timeline."""
    timeline = sum(getattr(action, "duration", 0.0) for action in plan.actions)
    return max(plan.duration or 0.0, timeline)


def simulation_cost(steps: float, bones: int, traced_steps: float = 0.0) -> float:
    """Estimated wall seconds of ``steps`` physics steps of a rig of ``bones`` bones, of which
    ``traced_steps`` are written to a trace."""
    step = bones * SECONDS_PER_BONE_STEP + bones**2 * SECONDS_PER_BONE_PAIR_STEP
    return steps * step + traced_steps * SECONDS_PER_TRACED_STEP


class BudgetWatch:
    """A run's progress callback that stops it (``OverBudget``, caught by the runner, which
    saves what the run captured) when its measured pace, after WATCH_AFTER s, projects more
    than twice the budget: the estimate cannot see every cost (stiff joints take up to 64
    substeps a step).  ``then``: the callback it wraps (a progress bar), or None."""

    def __init__(self, source: object, total_steps: float, yes: bool, then=None) -> None:
        self.source, self.total, self.yes, self.then = source, max(total_steps, 1.0), yes, then
        self.done, self.start = 0, time.perf_counter()

    def __call__(self, steps: int) -> None:
        if self.then is not None:
            self.then(steps)
        self.done += steps
        if self.yes:
            return
        elapsed = time.perf_counter() - self.start
        projected = elapsed * self.total / self.done
        if elapsed >= WATCH_AFTER and projected > 2.0 * _limit():
            rate = self.done / elapsed
            raise OverBudget(
                f"{self.source}: stopped after {self.done:,} of {self.total:,.0f} steps: at the "
                f"measured {rate:,.0f} steps/s the run would take about {_duration(projected)}, "
                f"over {_duration(_limit())}; what it captured is saved; pass --yes to run it "
                f"to the end"
            )


def video_cost(frames: int, size: tuple[int, int]) -> float:
    """Estimated wall seconds of drawing and encoding ``frames`` frames of ``size`` pixels."""
    return frames * (SECONDS_PER_VIDEO_FRAME + size[0] * size[1] * SECONDS_PER_VIDEO_PIXEL)


def check_run(
    source: object, plan, h: float, bones: int, yes: bool, *, trace_every: int | None = None,
    tick: float | None = None,
) -> float:  # fmt: skip
    """Refuse (``check_budget``) the run of ``plan`` at step ``h`` on ``bones`` bones, traced
    every ``trace_every`` steps (None: no trace), recorded as device ticks of ``tick`` s
    (None: none); the run's number of steps."""
    steps = run_length(plan) / h
    traced = steps / trace_every if trace_every else 0.0
    seconds = simulation_cost(steps, bones, traced)
    what = f"{steps:,.0f} steps of h = {h:g} s, {bones} bones"
    if tick is not None:
        ticks = run_length(plan) / tick
        seconds += ticks * SECONDS_PER_TICK
        what = f"{ticks:,.0f} device ticks of {tick * 1e3:g} ms, {what}"
    check_budget(source, what, seconds, yes)
    return steps


def check_budget(source: object, what: str, seconds: float, yes: bool) -> None:
    """Refuse (``PuppetError``) work estimated at more than the limit unless ``yes``."""
    limit = _limit()
    if seconds <= limit or yes:
        return
    raise PuppetError(
        f"{source}: expected a run of at most {_duration(limit)}, got about {_duration(seconds)} "
        f"({what}); check h and the durations, or pass --yes to run it anyway"
    )


def _limit() -> float:
    text = os.environ.get("PUPPETCLI_RUN_LIMIT", "")
    if not text:
        return LIMIT
    try:
        limit = float(text)
    except ValueError:
        limit = math.nan
    if not 0.0 <= limit < math.inf:
        raise PuppetError(f"PUPPETCLI_RUN_LIMIT: expected seconds >= 0, got {shown(text)}")
    return limit


def _duration(seconds: float) -> str:
    if seconds < 60:
        return f"{seconds:.0f} s"
    if seconds < 3600:
        return f"{seconds / 60:.0f} min"
    if seconds < 86400 * 3:
        return f"{seconds / 3600:.1f} h"
    return f"{seconds / 86400:,.0f} days"
