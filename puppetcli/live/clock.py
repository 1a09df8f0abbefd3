"""The physics clock of a live session, locked to the wall clock.

Each display frame asks how many steps are due: the simulated time should equal the
wall time elapsed since the clock was anchored (at start and at every resume).  When
the steps of a frame cannot be done within the frame's budget, or the simulation lags
the wall by more than ``MAX_LAG``, the clock drops the backlog (re-anchors) and reports
itself behind (for a ``WINDOW`` after a drop, and whenever the measured real-time factor
is under ``SLOW``): the doll then moves slower than real time, visibly, instead of in
bursts.  ``rtf`` (simulated seconds per wall second) and ``headroom`` (how many times
faster than real time the steps themselves run) are measured over the last ``WINDOW``.
"""

from __future__ import annotations

import math
from collections import deque

__all__ = ["MAX_LAG", "RealTimeClock"]

MAX_LAG = 0.2  # s: a larger lag is dropped rather than caught up
WINDOW = 1.0  # s of wall time the rates are measured over
SLOW = 0.95  # a real-time factor under this (over a full window) is behind


class RealTimeClock:
    """Steps due per frame, pause/resume, and the measured rates (module docstring)."""

    def __init__(self, h: float, now: float, sim_time: float = 0.0) -> None:
        self.h = h
        self.paused = False
        self._dropped = -math.inf  # wall time of the last dropped backlog
        self._anchor(now, sim_time)
        self._samples: deque[tuple[float, float, float, int]] = deque()  # wall, sim, busy, n

    def _anchor(self, now: float, sim_time: float) -> None:
        self._wall0, self._sim0 = now, sim_time

    def due(self, now: float, sim_time: float) -> int:
        """Steps to take now to catch the wall clock up (0 while paused)."""
        if self.paused:
            return 0
        lag = self._sim0 + (now - self._wall0) - sim_time
        if lag > MAX_LAG:
            self._dropped = now
            self._anchor(now - MAX_LAG, sim_time)
            lag = MAX_LAG
        return max(0, math.floor(lag / self.h + 1e-9))

    def done(self, now: float, sim_time: float, busy: float, steps: int) -> None:
        """Report a frame's work: ``steps`` taken in ``busy`` s."""
        self._samples.append((now, sim_time, busy, steps))
        while len(self._samples) > 2 and now - self._samples[1][0] >= WINDOW:
            self._samples.popleft()

    @property
    def behind(self) -> bool:
        """The physics did not keep up: a backlog dropped within the window, or a real-time
        factor under ``SLOW`` over a full window."""
        if self.paused or not self._samples:
            return False
        now = self._samples[-1][0]
        full = now - self._samples[0][0] >= 0.9 * WINDOW
        return now - self._dropped < WINDOW or (full and self.rtf < SLOW)

    def pause(self, on: bool, now: float, sim_time: float) -> None:
        if self.paused and not on:
            self._anchor(now, sim_time)
            self._samples.clear()
        self.paused = on

    @property
    def rtf(self) -> float:
        """Simulated seconds per wall second over the window (1 when there is no window yet)."""
        if len(self._samples) < 2:
            return 1.0
        (w0, s0, _, _), (w1, s1, _, _) = self._samples[0], self._samples[-1]
        return (s1 - s0) / (w1 - w0) if w1 > w0 else 1.0

    @property
    def step_time(self) -> float:
        """Mean wall time of one step (s) over the window (0 before any step)."""
        busy = sum(s[2] for s in self._samples)
        steps = sum(s[3] for s in self._samples)
        return busy / steps if steps else 0.0

    @property
    def headroom(self) -> float:
        """h over the mean step time: how many times faster than real time steps can run."""
        step = self.step_time
        return self.h / step if step > 0 else math.inf
