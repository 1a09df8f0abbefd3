"""The live physics clock: steps due against elapsed wall time, pause, dropped backlog, rates."""

from __future__ import annotations

import pytest

from puppetcli.live.clock import MAX_LAG, RealTimeClock


def test_steps_due_follow_the_wall_clock():
    c = RealTimeClock(0.005, now=100.0)
    assert c.due(100.0, 0.0) == 0
    assert c.due(100.0123, 0.0) == 2  # floor(12.3 ms / 5 ms)
    assert c.due(100.0123, 0.010) == 0
    assert c.due(100.1, 0.010) == 18  # (100 − 10) ms / 5 ms


def test_pause_stops_the_clock_and_resume_re_anchors():
    c = RealTimeClock(0.005, now=0.0)
    c.pause(True, now=0.05, sim_time=0.05)
    assert c.due(10.0, 0.05) == 0
    c.pause(False, now=10.0, sim_time=0.05)
    assert c.due(10.0, 0.05) == 0 and c.due(10.02, 0.05) == 4


def test_a_backlog_beyond_the_lag_limit_is_dropped_and_reported():
    c = RealTimeClock(0.001, now=0.0)
    due = c.due(5.0, 0.0)  # 5 s behind
    assert due == round(MAX_LAG / 0.001)
    c.done(5.0, 0.0, busy=0.01, steps=0)
    assert c.behind
    c.done(5.5, 0.5, busy=0.4, steps=500)
    assert c.behind  # within a window of the drop
    for i in range(1, 30):  # then keeping up for more than a window
        c.done(5.5 + 0.1 * i, 0.5 + 0.1 * i, busy=0.05, steps=100)
    assert not c.behind


def test_a_slow_window_is_behind():
    c = RealTimeClock(0.001, now=0.0)
    for i in range(1, 40):  # 0.9 simulated seconds per wall second
        c.done(0.05 * i, 0.045 * i, busy=0.05, steps=45)
    assert c.rtf == pytest.approx(0.9) and c.behind


def test_rates_over_the_window():
    c = RealTimeClock(0.002, now=0.0)
    sim = 0.0
    for i in range(1, 61):  # 60 frames of 1/60 s, each 8 steps of 2 ms taking 4 ms of work
        sim += 8 * 0.002
        c.done(i / 60, sim, busy=0.004, steps=8)
    assert c.rtf == pytest.approx(0.016 * 60, rel=1e-9)  # 16 ms simulated per 1/60 s
    assert c.step_time == pytest.approx(0.0005) and c.headroom == pytest.approx(4.0)
